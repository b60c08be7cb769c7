"""``thermcap bench analysis``'s recording line: a file source recorded with analysis on and
off, on the scenes that cost the detector most, alternated in the same run.

The goal (issue #40): with analysis on, a file source records at >= 0.5x its rate without it
on any scene. A file source waits for the detector (every frame is analysed), so the ratio is
what an import of that scene costs for its analysis. The rate is the recording's own
``timing.achieved_fps`` (first to last frame), as ``thermcap record --json`` reports it; the
detector process's start (an interpreter and scipy, about 0.3 s) is before the first frame.
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.raw import RawSource

__all__ = ["SCENES", "record_vs_no_analysis"]

# The worst cases: noise just below the bound where whole frames are set aside (most cells
# candidates, the region cap biting), every pixel a candidate (the candidate-fraction cap), and
# a flat scene (no candidates: the background estimate alone, against the writer's fastest).
SCENES: dict[str, Callable[[np.random.Generator, int, int, int], np.ndarray]] = {
    "gaussian_noise_45_counts": lambda rng, n, h, w: (2000 + rng.normal(0, 45, (n, h, w))).astype("<u2"),
    "uniform_noise": lambda rng, n, h, w: rng.integers(0, 16383, (n, h, w), dtype=np.uint16).astype("<u2"),
    "flat": lambda rng, n, h, w: np.full((n, h, w), 2000, "<u2"),
}
SIZES = ((640, 512), (320, 256))


def _record(path: Path, w: int, h: int, root: Path, analysis: bool) -> dict[str, Any]:
    shutil.rmtree(root, ignore_errors=True)
    res = Recorder(RawSource(str(path), width=w, height=h), root, recover_leftovers=False, analysis=analysis).run()
    if res.error is not None:
        raise RuntimeError(f"bench recording failed: {res.error}")
    out = {"fps": float(res.timing.get("achieved_fps") or 0.0), "skipped": res.analysis_skipped,
           "frames": res.frames_written}
    if res.analysis_runner:
        out["runner"] = res.analysis_runner["runner"]
        out["detector_ms_per_frame"] = round(1e3 * res.analysis_runner["cpu_s"] / max(1, res.frames_written), 3)
        out["answered_in_recorder"] = res.analysis_runner["answered_in_recorder"]
    shutil.rmtree(root, ignore_errors=True)
    return out


def record_vs_no_analysis(frames_640: int = 400, rounds: int = 3, workdir: str | None = None) -> dict[str, Any]:
    """Per scene and size: the median fps with and without analysis over ``rounds`` alternated
    pairs, and their ratio (goal >= 0.5). 320x256 records 4x the frames, for the same bytes."""
    rng = np.random.default_rng(5)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        for name, make in SCENES.items():
            for w, h in SIZES:
                n = frames_640 * (640 * 512) // (w * h)
                path = Path(tmp) / f"{name}_{w}x{h}.raw"
                make(rng, n, h, w).tofile(path)
                on, off, runs = [], [], []
                for _ in range(rounds):
                    run = _record(path, w, h, Path(tmp) / "root", analysis=True)
                    on.append(run["fps"])
                    runs.append(run)
                    off.append(_record(path, w, h, Path(tmp) / "root", analysis=False)["fps"])
                path.unlink()
                fps_on, fps_off = statistics.median(on), statistics.median(off)
                # each round's on and off ran back to back: their ratio leaves out how the
                # machine's pace moved between rounds, which the medians' ratio keeps
                pairs = [a / b for a, b in zip(on, off, strict=True) if b]
                out[f"{name}_{w}x{h}"] = {
                    "fps_with_analysis": round(fps_on, 1), "fps_without": round(fps_off, 1),
                    "ratio": round(fps_on / fps_off, 3) if fps_off else None, "goal": 0.5,
                    "ratio_rounds": [round(x, 3) for x in pairs],
                    "ratio_rounds_median": round(statistics.median(pairs), 3) if pairs else None,
                    "frames_skipped": sum(r["skipped"] for r in runs), "runner": runs[0].get("runner"),
                    "detector_ms_per_frame": statistics.median(r.get("detector_ms_per_frame", 0.0) for r in runs),
                    # frames too flat for a target, answered without the detector's process
                    "answered_in_recorder": runs[0].get("answered_in_recorder", 0),
                    "rounds": rounds, "frames": n}
    return out


def print_lines(res: dict[str, Any]) -> list[str]:
    lines = ["file source recorded with analysis on vs off (median of alternated rounds; goal >= 0.5x):"]
    for name, r in res.items():
        lines.append(f"  {name:34} {r['fps_with_analysis']:>8} vs {r['fps_without']:>8} fps = {r['ratio']}x "
                     f"(rounds' median {r['ratio_rounds_median']}x)  "
                     f"(detector {r['detector_ms_per_frame']} ms a frame in a {r['runner']}, "
                     f"{r['frames_skipped']} frames skipped, {r['answered_in_recorder']} too flat to send)")
    return lines
