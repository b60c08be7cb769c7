"""``thermcap bench index``: what the index costs a fleet, and whether it answers at that size.

Three figures, each from one run:

- **Index bytes per camera-hour.** A real session is recorded, analysed, archived in png16 and
  jxl, and indexed. Its bytes come from SQLite's ``dbstat``, table by table and index by
  index, and are scaled to an hour at 60 fps, then to a year of a 100-camera fleet at
  8 hours a day. Twice: as recorded, and with a target in every frame (the worst case for the
  rows a search reads). The frames file each session keeps beside its archives (its frame times
  and hashes, ``api.reading.frame_columns``) is reported apart: it is not in the database.
- **A catalog page** (``GET /api/v1/sessions``, 50 a page, newest first), p50 over a catalog of
  ``sessions`` synthetic sessions. Goal: < 50 ms at 100,000.
- **A frame search** (``GET /api/v1/frames?max_grade=0.3&min_target_c=T``), p50 over
  ``frames`` synthetic frames, 5% of them with a target. Goal: < 500 ms at 10 million.

The API is the real one, in process (FastAPI's TestClient), over SQLite or over the PostgreSQL
``--db`` names. On PostgreSQL a fresh database is made on that server and dropped afterwards.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_index", "print_table"]

HOUR_FRAMES = 3600 * 60
FLEET_CAMERA_HOURS_A_YEAR = 100 * 8 * 365


def _index_bytes(tmp: Path) -> dict[str, Any]:
    import json
    import shutil
    import sqlite3

    from thermcap.api.db import make_engine, migrate
    from thermcap.api.indexing import index_root
    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource
    from thermcap.recorder.storage.layout import SessionLayout

    root = tmp / "real"
    n = 600
    Recorder(SimSource(width=64, height=48, frames=n, paced=False, seed=3, first_cue_s=0.1), root,
             session_id="real").run()
    archive_session(DataRoot.of(root).session_dir("real"), ["png16", "jxl"])
    # The worst case for the database: a target in every frame (every second has its row, full).
    shutil.copytree(DataRoot.of(root).session_dir("real"), DataRoot.of(root).session_dir("hot"))
    hot = SessionLayout.of(DataRoot.of(root).session_dir("hot"))
    meta = json.loads(hot.session_json.read_text())
    hot.session_json.write_text(json.dumps({**meta, "session_id": "hot"}))
    with open(hot.analysis_jsonl, "w") as f:
        for i in range(n):
            f.write(json.dumps({"index": i, "thermal_analysis": {"thermal_contrast_grade": 0.5},
                                "targets": [{"max_temp_c": 30.0 + i % 17}]}) + "\n")
    out: dict[str, Any] = {"frames": n}
    for name in ("real", "hot"):
        path = tmp / f"{name}.sqlite"
        engine = make_engine(f"sqlite:///{path}")
        migrate(engine)
        before = _table_bytes(path)
        index_root(engine, root)
        engine.dispose()
        with sqlite3.connect(path) as c:
            c.execute("PRAGMA foreign_keys=ON")
            c.execute("DELETE FROM sessions WHERE id != ?", (name,))  # the other session's rows
        with sqlite3.connect(path, isolation_level=None) as c:
            c.execute("VACUUM")
        after = _table_bytes(path)
        grown = {k: v - before.get(k, 0) for k, v in after.items() if v - before.get(k, 0) > 0}
        per_frame = sum(grown.values()) / n
        files = sum(p.stat().st_size for p in DataRoot.of(root).frames_index(name).glob("*.parquet"))
        out["every_frame_a_target" if name == "hot" else "recorded"] = {
            "bytes_by_table": grown, "bytes_per_frame": round(per_frame, 1),
            "bytes_per_camera_hour": round(per_frame * HOUR_FRAMES),
            "gb_per_fleet_year": round(per_frame * HOUR_FRAMES * FLEET_CAMERA_HOURS_A_YEAR / 1e9, 1),
            "frames_file_bytes_per_frame": round(files / n, 1),
            "frames_file_bytes_per_camera_hour": round(files / n * HOUR_FRAMES)}
    rec = out["recorded"]
    out.update({k: rec[k] for k in ("bytes_by_table", "bytes_per_frame", "bytes_per_camera_hour",
                                    "gb_per_fleet_year")})
    out["goal_bytes_per_camera_hour"] = 10_000_000
    return out


def _table_bytes(path: Path) -> dict[str, int]:
    import sqlite3

    with sqlite3.connect(path) as c:
        try:
            # the bytes in use, not whole pages: a 10-second session fills no page of its own
            return dict(c.execute("SELECT name, SUM(pgsize - unused) FROM dbstat GROUP BY name").fetchall())
        except sqlite3.OperationalError:  # a SQLite built without dbstat: the whole file
            return {"(file)": path.stat().st_size}


def _fresh_postgres(url: str) -> tuple[str, Any]:
    from sqlalchemy import create_engine, text

    name = f"thermcap_bench_{uuid.uuid4().hex[:8]}"
    admin = create_engine(url.replace("postgresql://", "postgresql+psycopg://", 1), isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    base, _, _ = url.rpartition("/")

    def drop() -> None:
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()
    return f"{base}/{name}", drop


def _fill(engine: Any, sessions: int, frames: int, seed: int = 7) -> float:
    from sqlalchemy import insert

    from thermcap.api import db

    t0 = 1_800_000_000_000_000_000
    per = max(1, frames // sessions)
    start = time.perf_counter()
    with engine.begin() as conn:
        if conn.dialect.name == "sqlite":
            conn.exec_driver_sql("PRAGMA synchronous=OFF")
        rows: list[dict[str, Any]] = []
        for i in range(sessions):
            begin = t0 + i * 10**12
            rows.append({"id": f"s{i:07d}", "path": f"/data/sessions/s{i:07d}", "sensor": "SIM",
                         "sensor_id": f"CAM{i % 100:03d}", "width": 640, "height": 512, "fps": 60.0,
                         "start_ns": begin, "end_ns": begin + per * 16_666_667, "frames": per, "frames_dropped": 0,
                         "radiometric_model": '{"kind": "linear"}', "status": "complete", "min_grade": 0.2,
                         "max_grade": 1.0, "has_targets": True, "has_slew_to_cue": False, "coverage": "[]",
                         "source_deleted": False, "fingerprint": "x", "indexed_at": 0, "summary": None})
            if len(rows) >= 20_000:
                conn.execute(insert(db.sessions), rows)
                rows = []
        if rows:
            conn.execute(insert(db.sessions), rows)
    import numpy as np

    from thermcap.api.reading.frame_search import HOT_FRAME

    gen = np.random.default_rng(seed)
    batch: list[dict[str, Any]] = []
    with engine.begin() as conn:
        for i in range(sessions):
            hot = np.flatnonzero(gen.random(per) < 0.05)  # 5% of frames hold a target
            if not len(hot):
                continue
            rec = np.zeros(len(hot), HOT_FRAME)
            rec["idx"], rec["target_count"] = hot, 1
            rec["max_target_temp_c"] = np.round(gen.uniform(20, 80, len(hot)), 3)
            rec["grade"] = gen.random(len(hot))
            second = hot // 60
            rec["offset_ns"] = (hot % 60) * 16_666_667
            first_second = (t0 + i * 10**12) // 10**9
            for sec in np.unique(second):
                part = rec[second == sec]
                batch.append({"session_id": f"s{i:07d}", "second": int(first_second + sec),
                              "max_target_temp_c": float(part["max_target_temp_c"].max()),
                              "min_target_temp_c": float(part["max_target_temp_c"].min()),
                              "min_grade": float(part["grade"].min()), "frames": part.tobytes()})
            if len(batch) >= 50_000:
                conn.execute(insert(db.target_seconds), batch)
                batch = []
        if batch:
            conn.execute(insert(db.target_seconds), batch)
        conn.exec_driver_sql("ANALYZE")  # both databases plan from fresh statistics
    return time.perf_counter() - start


def _p50(fn: Any, n: int = 30) -> float:
    fn(0)  # warm
    times = []
    for i in range(n):
        t = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1000


def bench_index(sessions: int = 100_000, frames: int = 10_000_000, db_url: str | None = None) -> dict[str, Any]:
    from fastapi.testclient import TestClient

    from thermcap.api.app import create_app
    from thermcap.api.db import make_engine, migrate
    from thermcap.api.settings import Settings

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="thermcap-bench-index-") as tmp_s:
        tmp = Path(tmp_s)
        out["index_size"] = _index_bytes(tmp)
        drop = None
        if db_url and db_url.startswith("postgresql"):
            url, drop = _fresh_postgres(db_url)
        else:
            url = f"sqlite:///{tmp / 'fleet.sqlite'}"
        try:
            engine = make_engine(url)
            migrate(engine)
            fill_s = _fill(engine, sessions, frames)
            engine.dispose()
            settings = Settings(root=tmp / "empty", database_url=url, tokens={}, rescan_interval_s=0)
            with TestClient(create_app(settings, index_on_start=False)) as c:
                first = c.get("/api/v1/sessions", params={"limit": 50}).json()
                cursor = first["next_cursor"]
                catalog = _p50(lambda i: c.get("/api/v1/sessions", params={"limit": 50}))
                deeper = _p50(lambda i: c.get("/api/v1/sessions", params={"limit": 50, "cursor": cursor}))
                search = _p50(lambda i: c.get("/api/v1/frames", params={"max_grade": 0.3,
                                                                        "min_target_c": 40 + i % 20, "limit": 100}))
                hits = len(c.get("/api/v1/frames", params={"max_grade": 0.3, "min_target_c": 40,
                                                           "limit": 100}).json()["items"])
        finally:
            if drop is not None:
                drop()
    out.update({"database": "postgresql" if drop is not None else "sqlite", "sessions": sessions, "frames": frames,
                "fill_s": round(fill_s, 1), "catalog_page_p50_ms": round(catalog, 2),
                "catalog_next_page_p50_ms": round(deeper, 2), "frame_search_p50_ms": round(search, 2),
                "frame_search_hits_first_page": hits, "goals": {"catalog_page_p50_ms": 50, "frame_search_p50_ms": 500},
                "cpus": os.cpu_count()})
    return out


def print_table(res: dict[str, Any]) -> str:
    size = res["index_size"]
    lines = []
    for label, key in (("recorded session", "recorded"), ("a target in every frame", "every_frame_a_target")):
        part = size[key]
        lines += [f"index ({label}): {part['bytes_per_frame']} bytes a frame, "
                  f"{part['bytes_per_camera_hour'] / 1e6:.2f} MB a camera-hour at 60 fps (goal <= 10), "
                  f"{part['gb_per_fleet_year']} GB a year for 100 cameras x 8 h a day; frames file beside the "
                  f"archives {part['frames_file_bytes_per_camera_hour'] / 1e6:.1f} MB a camera-hour",
                  "  by table and index: " + ", ".join(f"{k} {v / size['frames']:.1f} B/frame"
                                                       for k, v in sorted(part["bytes_by_table"].items()))]
    lines += [f"{res['database']}: {res['sessions']:,} sessions, {res['frames']:,} frames "
              f"(filled in {res['fill_s']} s)",
              f"  catalog page p50 {res['catalog_page_p50_ms']} ms (next page {res['catalog_next_page_p50_ms']} ms; "
              f"goal < 50 ms)",
              f"  frame search p50 {res['frame_search_p50_ms']} ms ({res['frame_search_hits_first_page']} on the first "
              f"page; goal < 500 ms)"]
    return "\n".join(lines)
