"""An index made before the frames files: migration 0008 turns its hex frame hashes into 32
bytes, 0009 keeps its frame rows aside (``frames_legacy``), and the next scan writes each
session's frames file from them, every value kept, so a session served from a bucket alone
(never indexed again from a folder) still serves its frames. On SQLite here, on PostgreSQL in
the system tier (``test_legacy_frames_on_postgresql``)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from sqlalchemy import inspect, select, text

from thermcap.api import db
from thermcap.api.indexing import convert_legacy_frames
from thermcap.api.reading.frame_columns import FrameColumnsCache
from thermcap.archive.blobs import open_store

H = [hashlib.sha256(bytes([i])).hexdigest() for i in range(4)]


def _alembic(conn):
    cfg = Config()
    cfg.set_main_option("script_location", str(db.__file__).replace("db.py", "migrations"))
    cfg.attributes["connection"] = conn
    return cfg


def _old_frames_table() -> sa.Table:
    """``frames`` as every index before 0009 had it (hashes as hex before 0008)."""
    return sa.Table("frames", sa.MetaData(),
                    sa.Column("session_id", sa.String(128), primary_key=True),
                    sa.Column("idx", sa.Integer, primary_key=True),
                    sa.Column("timestamp_ns", sa.BigInteger, nullable=False), sa.Column("segment", sa.String(64)),
                    sa.Column("grade", sa.Float), sa.Column("slew_to_cue", sa.Boolean, nullable=False),
                    sa.Column("target_count", sa.Integer, nullable=False), sa.Column("max_target_temp_c", sa.Float),
                    sa.Column("sha256", sa.String(64)), sa.Column("sidecar_sha256", sa.String(64)))


def _index_before_0009(engine) -> None:
    """An index at 0007 with rows for "m" (still current) and "n" (indexed anew since: its
    ``frames_key`` names a file, its rows are stale), then migrated to the head."""
    with engine.begin() as conn:
        command.upgrade(_alembic(conn), "0007")
        frames = _old_frames_table()
        frames.create(conn)
        for sid in ("m", "n"):
            conn.execute(text("INSERT INTO sessions (id, path, frames, frames_dropped, has_targets, "
                              "has_slew_to_cue, source_deleted, fingerprint, indexed_at, frames_key) VALUES "
                              "(:sid, :path, 2, 0, true, false, false, 'fp', 0, :key)"),
                         {"sid": sid, "path": sid, "key": None if sid == "m" else "index/frames/n/new.parquet"})
        conn.execute(frames.insert(), [
            {"session_id": "m", "idx": 0, "timestamp_ns": 5_000_000_001, "segment": "0000.mcap", "grade": 0.25,
             "slew_to_cue": False, "target_count": 2, "max_target_temp_c": 61.5, "sha256": H[0],
             "sidecar_sha256": H[1]},
            {"session_id": "m", "idx": 1, "timestamp_ns": 5_016_666_668, "segment": "0000.mcap", "grade": None,
             "slew_to_cue": True, "target_count": 0, "max_target_temp_c": None, "sha256": H[2],
             "sidecar_sha256": None},
            {"session_id": "n", "idx": 0, "timestamp_ns": 1, "segment": None, "grade": None, "slew_to_cue": False,
             "target_count": 0, "max_target_temp_c": None, "sha256": H[3], "sidecar_sha256": None}])
    db.migrate(engine)


def check_legacy_frames(engine, root: Path) -> None:
    _index_before_0009(engine)
    with engine.connect() as conn:
        names = inspect(conn).get_table_names()
        assert "frames" not in names and "frames_legacy" in names
        stored = conn.execute(text("SELECT sha256 FROM frames_legacy WHERE idx = 1 AND session_id = 'm'")).scalar()
        assert bytes(stored) == bytes.fromhex(H[2])  # 0008: 32 bytes, not 64 characters
    store = open_store(root)
    assert convert_legacy_frames(engine, store) == ["m"]  # "n" was indexed anew: its rows were stale
    cols = FrameColumnsCache(engine, store).get("m")
    assert [cols.row(i)["pixel_digest"] for i in range(2)] == [H[0], H[2]] and cols.digest == "sha256"
    assert cols.row(0)["sidecar_digest"] == H[1] and cols.row(1)["sidecar_digest"] is None
    assert cols.row(0)["timestamp_ns"] == 5_000_000_001 and cols.row(1)["segment"] == "0000.mcap"
    assert (cols.row(0)["grade"], cols.row(1)["grade"], cols.row(1)["slew_to_cue"]) == (0.25, None, True)
    with engine.connect() as conn:
        assert "frames_legacy" not in inspect(conn).get_table_names()
        seconds = conn.execute(select(db.target_seconds.c.second, db.target_seconds.c.max_target_temp_c)
                               .where(db.target_seconds.c.session_id == "m")).all()
    assert [tuple(r) for r in seconds] == [(5, 61.5)]
    assert convert_legacy_frames(engine, store) == []  # nothing left: a second scan is a no-op
    db.migrate(engine)


def test_legacy_frames_on_sqlite(tmp_path):
    engine = db.make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    check_legacy_frames(engine, tmp_path)


_FRAMES_INDEXES = {"ix_frames_time", "ix_frames_hot", "ix_frames_graded"}


def _rows(conn) -> list[tuple]:
    return [tuple(r) for r in conn.execute(text("SELECT session_id, idx, timestamp_ns, max_target_temp_c, sha256 "
                                                 "FROM frames ORDER BY session_id, idx"))]


def check_downgrade(engine, root: Path) -> None:
    """0009's downgrade gives the code before it a ``frames`` table with its indexes. The rows
    kept aside come back as they were. A session whose frames went to a file is scanned again by
    that code (its fingerprint cleared), whether or not its rows had been converted. The chain
    goes on down to 0007 and back up."""
    _index_before_0009(engine)
    db.downgrade(engine, "0008")
    with engine.connect() as conn:
        insp = inspect(conn)
        assert "frames" in insp.get_table_names() and "frames_legacy" not in insp.get_table_names()
        assert "target_seconds" not in insp.get_table_names()
        assert "frames_key" not in {c["name"] for c in insp.get_columns("sessions")}
        assert {i["name"] for i in insp.get_indexes("frames")} >= _FRAMES_INDEXES
        rows = _rows(conn)
        assert [r[:4] for r in rows] == [("m", 0, 5_000_000_001, 61.5), ("m", 1, 5_016_666_668, None),
                                         ("n", 0, 1, None)]
        assert [bytes(r[4]) for r in rows] == [bytes.fromhex(h) for h in (H[0], H[2], H[3])]  # 0008's bytes
        prints = dict(conn.execute(text("SELECT id, fingerprint FROM sessions")).all())
    assert prints == {"m": "fp", "n": ""}  # "n"'s rows are older than its file: scanned again
    db.downgrade(engine, "0007")  # 0008 turns the hashes back to hex, 0007 drops its indexes
    with engine.connect() as conn:
        assert [r[4] for r in _rows(conn)] == [H[0], H[2], H[3]]
    db.migrate(engine)  # and up again: the rows are kept aside once more
    with engine.connect() as conn:
        names = inspect(conn).get_table_names()
        assert "frames" not in names and "frames_legacy" in names
    store = open_store(root)
    assert convert_legacy_frames(engine, store) == ["m", "n"]  # no file names "n" now: its rows serve
    db.downgrade(engine, "0008")  # every row converted: an empty table, every session scanned again
    with engine.connect() as conn:
        assert _rows(conn) == []
        assert {i["name"] for i in inspect(conn).get_indexes("frames")} >= _FRAMES_INDEXES
        assert dict(conn.execute(text("SELECT id, fingerprint FROM sessions")).all()) == {"m": "", "n": ""}
    db.migrate(engine)


def test_downgrade_on_sqlite(tmp_path):
    engine = db.make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    check_downgrade(engine, tmp_path)
