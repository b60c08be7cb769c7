"""The index keeps no row per frame: each session's frame facts are one Parquet file in the blob
store, named by the session's row, replaced whole when the session changes and deleted when it
goes; the database grows by the seconds that hold a target, at most 3,600 rows a camera-hour."""

from __future__ import annotations

import json
import shutil
import sqlite3

import pyarrow.parquet as pq
import pytest
from sqlalchemy import select

from thermcap.api import db
from thermcap.api.db import make_engine, migrate
from thermcap.api.indexing import index_root
from thermcap.api.reading.frame_columns import FrameColumnsCache
from thermcap.archive.archiver import archive_session
from thermcap.archive.blobs import open_store
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.layout import SessionLayout

FRAMES = 240  # 4 seconds at 60 fps


@pytest.fixture()
def root(tmp_path):
    Recorder(SimSource(width=64, height=48, frames=FRAMES, paced=False, seed=3), tmp_path, session_id="s").run()
    archive_session(tmp_path / "sessions" / "s", ["png16"])
    return tmp_path


def _key(engine) -> str:
    with engine.connect() as conn:
        return conn.execute(select(db.sessions.c.frames_key).where(db.sessions.c.id == "s")).scalar_one()


def _target_in_every_frame(session_dir, temp=lambda i: 30.0 + i % 17) -> None:
    with open(SessionLayout.of(session_dir).analysis_jsonl, "w") as f:
        for i in range(FRAMES):
            f.write(json.dumps({"index": i, "thermal_analysis": {"thermal_contrast_grade": 0.5},
                                "targets": [{"max_temp_c": temp(i)}]}) + "\n")


def test_the_frames_file_holds_the_manifests_facts_and_is_replaced_whole(root):
    engine = make_engine(f"sqlite:///{root / 'index.sqlite'}")
    migrate(engine)
    index_root(engine, root)
    first = _key(engine)
    manifest = json.loads(SessionLayout.of(root / "sessions" / "s").manifest.read_text())
    table = pq.read_table(root / first)  # anyone's Parquet reader opens it
    assert table.num_rows == FRAMES
    assert [h.hex() for h in table.column("blake3").to_pylist()] == manifest["frames"]["blake3"]
    assert table.column("timestamp_ns").to_pylist() == manifest["frames"]["timestamps_ns"]

    _target_in_every_frame(root / "sessions" / "s")  # `thermcap analyze` ran: a new indexed state
    assert index_root(engine, root).indexed == ["s"]
    second = _key(engine)
    assert second != first and not (root / first).exists() and (root / second).is_file()
    cols = FrameColumnsCache(engine, open_store(root)).get("s")
    assert cols.row(7)["max_target_temp_c"] == 37.0 and cols.row(7)["pixel_digest"] == manifest["frames"]["blake3"][7]

    shutil.rmtree(root / "sessions" / "s")
    assert index_root(engine, root).removed == ["s"]
    assert not (root / second).exists()


def test_a_camera_hour_costs_the_database_under_10_mb_with_a_target_in_every_frame(root):
    _target_in_every_frame(root / "sessions" / "s")
    path = root / "index.sqlite"
    engine = make_engine(f"sqlite:///{path}")
    migrate(engine)
    index_root(engine, root)
    engine.dispose()
    with sqlite3.connect(path) as c:
        used = dict(c.execute("SELECT name, SUM(pgsize - unused) FROM dbstat GROUP BY name").fetchall())
        seconds = c.execute("SELECT COUNT(*) FROM target_seconds").fetchone()[0]
    assert seconds <= FRAMES // 60 + 1  # a row per second (4 s can touch 5), not per frame
    per_second = used["target_seconds"] + used["ix_target_seconds_hot"] + used["sqlite_autoindex_target_seconds_1"]
    assert per_second / FRAMES * 3600 * 60 < 10e6


def test_a_frames_file_gone_answers_503_names_the_repair_and_the_next_scan_rewrites_it(root):
    from fastapi.testclient import TestClient

    from thermcap.api.app import create_app
    from thermcap.api.settings import Settings

    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        (root / _key(c.app.state.engine)).unlink()
        r = c.get("/api/v1/sessions/s/frames")
        assert r.status_code == 503 and "thermcap index --force" in r.text
        # the next scan looks at the file rather than trusting the row: it is written again
        assert index_root(c.app.state.engine, root).indexed == ["s"]
        assert (root / _key(c.app.state.engine)).is_file()
        assert len(c.get("/api/v1/sessions/s/frames").json()["items"]) == FRAMES


def test_the_frames_file_gives_back_every_value_it_was_given():
    """Whatever mix of missing hashes, grades, targets and segments, Parquet gives back each."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from thermcap.api.reading.frame_columns import FrameColumns

    digest = st.none() | st.binary(min_size=32, max_size=32).map(bytes.hex)
    row = st.fixed_dictionaries({
        "timestamp_ns": st.integers(0, 2**62), "segment": st.none() | st.sampled_from(["0000.mcap", "0001.mcap"]),
        "digest": st.sampled_from(["blake3", "sha256"]), "pixel_digest": digest, "sidecar_digest": digest,
        "grade": st.none() | st.floats(0, 1), "target_count": st.integers(0, 1000),
        "max_target_temp_c": st.none() | st.floats(-273.15, 5000), "slew_to_cue": st.booleans()})

    @settings(max_examples=60, deadline=None)
    @given(st.lists(row, max_size=40))
    def round_trip(rows):
        name = rows[0]["digest"] if rows else "blake3"  # one hash a session
        rows = [{**r, "digest": name} for r in rows]
        back = FrameColumns.from_parquet("p", FrameColumns.from_rows("p", rows, name).to_parquet())
        assert back.digest == name
        assert [{k: v for k, v in back.row(i).items() if k != "idx"} for i in range(len(back))] == rows

    round_trip()
