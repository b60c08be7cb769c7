"""``thermcap bench series``: a region's time series against decoding every frame.

The anchor, measured in the same run on the same session: every frame decoded and converted to
°C whole, what a naive series costs. The series converts only the tool's rectangle; its floor
is the decode itself.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from recorder.capture.recorder import Recorder
from recorder.capture.sources.sim import SimSource
from recorder.storage.reader import iter_session_frames
from recorder.thermography.measure import measure, parse_tool
from recorder.thermography.series import region_series

__all__ = ["bench_series"]


def bench_series(seconds: float = 20.0, tool: str = "box:300,200,339,239",
                 workdir: str | None = None) -> dict[str, Any]:
    n = int(seconds * 60)
    t_ = parse_tool(tool)
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        rec = Recorder(SimSource(width=640, height=512, fps=60, frames=n, paced=False, seed=5), tmp, session_id="s",
                       analysis=False, recover_leftovers=False)
        if not rec.run().ok:
            raise RuntimeError("the benchmark session did not record cleanly")
        model = rec.source.model
        d = Path(tmp) / "sessions" / "s"
        t0 = time.perf_counter()
        decoded = sum(1 for _ in iter_session_frames(d))
        decode_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        naive = [measure(np.asarray(model.to_celsius(f.pixels), dtype=np.float32), t_).max_c
                 for f in iter_session_frames(d)]
        naive_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        points = region_series(((f.index, f.log_time, f.pixels) for f in iter_session_frames(d)), t_, "max",
                               lambda _i, c: np.asarray(model.to_celsius(c)))
        series_s = time.perf_counter() - t0
    same = [p["celsius"] for p in points] == naive
    return {"frames": decoded, "tool": tool, "decode_all_s": round(decode_s, 3),
            "naive_full_frame_s": round(naive_s, 3), "series_s": round(series_s, 3),
            "series_vs_naive": round(naive_s / series_s, 2), "series_vs_decode_only": round(series_s / decode_s, 2),
            "same_values": same, "series_fps": round(decoded / series_s, 1)}
