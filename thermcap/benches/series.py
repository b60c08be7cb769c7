"""``thermcap bench series``: a region's time series over an archived session against decoding
every frame of it, in one run on the same session.

The anchor is the full decode: every frame through the API's frame reader, each checked against
its sha256, on the same two threads the series uses. That is what a series cost before the
frame summary existed, and what it still costs for a session archived without one.

The series is then timed three ways:

- the whole frame, from the summary;
- a box, from its TIFF strips alone;
- the same box with the summary withheld (the frame-by-frame path).

The three must give the same numbers as the frame-by-frame path. Each time is also
extrapolated to a 1-hour session at 60 fps, from the per-frame cost.
"""

from __future__ import annotations

import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_series"]

HOUR_FRAMES = 3600 * 60


def bench_series(seconds: float = 60.0, tool: str = "box:300,200,339,239", *, threads: int = 2,
                 workdir: str | None = None) -> dict[str, Any]:
    from sqlalchemy import select

    from thermcap.api import db
    from thermcap.api.db import make_engine, migrate
    from thermcap.api.indexing import index_session
    from thermcap.api.reading.frames import FrameReader
    from thermcap.api.reading.regions import RegionReader
    from thermcap.archive.archiver import DEFAULT_FORMATS, archive_session
    from thermcap.archive.blobs import open_store
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource
    from thermcap.recorder.exports.render import session_model
    from thermcap.recorder.thermography.measure import parse_tool

    n = int(seconds * 60)
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        root = Path(tmp)
        rec = Recorder(SimSource(width=640, height=512, fps=60, frames=n, paced=False, seed=5), root,
                       session_id="s", analysis=False, recover_leftovers=False)
        if not rec.run().ok:
            raise RuntimeError("the benchmark session did not record cleanly")
        d = DataRoot.of(root).session_dir("s")
        archive_session(d, list(DEFAULT_FORMATS), delete_source=True)  # served from its archive, as in the field
        engine = make_engine(f"sqlite:///{DataRoot.of(root).index_db}")
        migrate(engine)
        index_session(engine, d)
        with engine.connect() as conn:
            row = dict(conn.execute(select(db.sessions).where(db.sessions.c.id == "s")).mappings().one())
        store = open_store(root)
        times = dict(enumerate(FrameReader(engine, store, root).columns.get("s").timestamp_ns.tolist()))
        model = session_model(row["radiometric_model"])

        def reader(cache: int = 0) -> tuple[FrameReader, RegionReader]:
            frames = FrameReader(engine, store, root, cache_frames=cache)
            return frames, RegionReader(frames, engine, store, threads=threads)

        frames, _ = reader()
        t0 = time.perf_counter()
        with ThreadPoolExecutor(threads) as pool:
            decoded = sum(1 for _ in pool.map(lambda i: frames.pixels("s", i), range(n)))
        decode_s = time.perf_counter() - t0
        box = parse_tool(tool)
        whole = parse_tool(f"box:0,0,{row['width'] - 1},{row['height'] - 1}")
        runs: dict[str, Any] = {}
        for name, t, summary in (("whole_frame_summary", whole, True), ("box_strips", box, True),
                                 ("box_frame_by_frame", box, False), ("whole_frame_by_frame", whole, False)):
            _, regions = reader()
            use = row if summary else {**row, "summary": None}
            res = regions.series(use, t, "max", range(n), lambda _i: model, times)
            runs[name] = {"method": res.method, "seconds": round(res.seconds, 4), "frames_decoded": res.frames_decoded,
                          "x_faster_than_full_decode": round(decode_s / res.seconds, 1) if res.seconds else None,
                          "one_hour_s": round(res.seconds / n * HOUR_FRAMES, 2),
                          "values": [p["celsius"] for p in res.points]}
    same = (runs["box_strips"]["values"] == runs["box_frame_by_frame"]["values"]
            and runs["whole_frame_summary"]["values"] == runs["whole_frame_by_frame"]["values"])
    for r in runs.values():
        r.pop("values")
    return {"frames": decoded, "tool": tool, "threads": threads,
            "full_decode_s": round(decode_s, 3), "full_decode_one_hour_s": round(decode_s / n * HOUR_FRAMES, 1),
            "runs": runs, "same_values": same}


def print_table(res: dict[str, Any]) -> str:
    lines = [f"{res['frames']} frames of 640x512; full decode {res['full_decode_s']} s "
             f"(one hour at 60 fps: {res['full_decode_one_hour_s']} s)"]
    for name, r in res["runs"].items():
        lines.append(f"  {name:22} {r['method']:8} {r['seconds']:9.3f} s  {r['x_faster_than_full_decode']:>7}x faster "
                     f"than the full decode; one hour {r['one_hour_s']} s")
    lines.append(f"same values: {res['same_values']}")
    return "\n".join(lines)
