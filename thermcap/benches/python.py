"""``thermcap bench python``: the Python paths against their anchors, measured in the same run.

- a whole session through the Zarr endpoint against h5py reading the same frames from the local
  HDF5 archive: format 3 (``xr.open_zarr(url, zarr_format=3, chunks=None)``: a request a shard;
  goal <= 1.5x) and format 2 (a request a frame, as before format 3 was served);
- the first frame through ``thermcap.open(url)`` against one raw frame GET with httpx (<= 2x);
- ``Session.to_xarray()`` opening: its time, and that it read no frame (it must not, however
  long the session); with ``hour=True`` also on a real one-hour session (216,000 frames at
  60 fps, recorded at 32x24: opening costs per frame of the table, not per pixel), with the
  memory it took (tracemalloc's peak) and the imports (xarray, dask) timed apart.

Each pair alternates over rounds and reports the median ratio: the machine is shared and noisy.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from thermcap.benches.harness import alternating, served, timed
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_one_hour_open", "bench_python"]


def _count_reads(session: Any) -> dict[str, int]:
    """Count the frames ``session`` reads from here on (opening a Dataset must read none)."""
    reads = {"n": 0}
    original = session.counts

    def counting(index: int) -> Any:
        reads["n"] += 1
        return original(index)

    session.counts = counting
    return reads


def bench_one_hour_open(fps: int = 60) -> dict[str, Any]:
    """``to_xarray()`` of a one-hour session: seconds to open (median of 3, imports warmed first),
    frames read while opening (0), and the peak Python memory it allocated."""
    import tracemalloc

    import thermcap
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    frames = fps * 3600
    t = time.perf_counter()
    import dask.array  # noqa: F401 - the imports, timed apart from opening
    import xarray  # noqa: F401
    imports = time.perf_counter() - t
    with tempfile.TemporaryDirectory(prefix="thermcap-bench-hour-") as tmp:
        root = Path(tmp)
        t = time.perf_counter()
        Recorder(SimSource(width=32, height=24, frames=frames, fps=fps, paced=False, seed=1), root,
                 session_id="hour", analysis=False).run()
        recorded = time.perf_counter() - t
        t = time.perf_counter()
        session = thermcap.open("hour", root=root)
        indexed = time.perf_counter() - t
        reads = _count_reads(session)
        times = []
        for _ in range(3):
            t = time.perf_counter()
            session.to_xarray()
            times.append(time.perf_counter() - t)
        tracemalloc.start()
        ds = session.to_xarray()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return {"frames": frames, "chunks": len(ds.counts.chunks[0]), "seconds": round(statistics.median(times), 4),
                "frames_read": reads["n"], "peak_python_mb": round(peak / 1e6, 1), "imports_s": round(imports, 3),
                "recorded_s": round(recorded, 1), "first_open_and_index_s": round(indexed, 2),
                "goal": "< 1 s, 0 read, memory bounded"}


def bench_python(frames: int = 600, width: int = 640, height: int = 512, rounds: int = 5,
                 hour: bool = False) -> dict[str, Any]:
    import h5py
    import httpx
    import numpy as np
    import xarray as xr

    import thermcap
    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    with tempfile.TemporaryDirectory(prefix="thermcap-bench-python-") as tmp:
        root = Path(tmp)
        Recorder(SimSource(width=width, height=height, frames=frames, paced=False, seed=1), root,
                 session_id="bench", analysis=False).run()
        session_dir = DataRoot.of(root).session_dir("bench")
        archive_session(session_dir, ["hdf5"])
        (h5,) = sorted((session_dir / "archive" / "hdf5").glob("*.h5"))
        with served(root) as url:
            session_url = f"{url}/api/v1/sessions/bench"

            def h5py_all() -> Any:
                with h5py.File(h5, "r") as f:
                    return f["frames"][...]

            def zarr3_all() -> Any:
                return xr.open_zarr(session_url + "/zarr", zarr_format=3, chunks=None).counts.values

            def zarr2_all() -> Any:
                return xr.open_zarr(session_url + "/zarr", zarr_format=2).counts.values

            for read in (zarr3_all, zarr2_all):
                if not np.array_equal(read(), h5py_all()):
                    raise RuntimeError(f"{read.__name__}: the Zarr endpoint's counts differ from the HDF5 archive's")
            whole = alternating(zarr3_all, h5py_all, rounds).to_dict()
            whole2 = alternating(zarr2_all, h5py_all, rounds).to_dict()

            with httpx.Client() as http:
                def raw_get() -> Any:
                    return http.get(f"{session_url}/frames/0", params={"format": "raw"}).content

                def open_first() -> Any:
                    return thermcap.open(session_url).frame(0).counts

                first = alternating(open_first, raw_get, rounds).to_dict()

            local = thermcap.open("bench", root=root)
            reads = _count_reads(local)
            opened = timed(lambda: local.to_xarray())
            out = {"frames": frames, "size": f"{width}x{height}", "rounds": rounds,
                   "zarr_whole_session_vs_h5py": {**whole, "goal": "<= 1.5"},
                   "zarr2_whole_session_vs_h5py": {**whole2, "goal": "the format 2 path, for comparison"},
                   "first_frame_open_vs_raw_get": {**first, "goal": "<= 2"},
                   "to_xarray_open": {"seconds": round(opened, 4), "frames_read": reads["n"], "goal": "< 1 s, 0 read"}}
    if hour:
        out["to_xarray_open_one_hour"] = bench_one_hour_open()
    return out


def bench_startup(rounds: int = 7) -> dict[str, Any]:
    """``thermcap --help`` and ``thermcap record --help`` against ``python -c "import click"``, each
    a fresh interpreter, alternated; the goal is <= 3x."""
    anchor = [sys.executable, "-c", "import click"]
    cases = {"thermcap --help": [sys.executable, "-m", "thermcap", "--help"],
             "thermcap record --help": [sys.executable, "-m", "thermcap", "record", "--help"]}

    def run(cmd: list[str]) -> Callable[[], Any]:
        return lambda: subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    return {name: {**alternating(run(cmd), run(anchor), rounds).to_dict(), "goal": "<= 3"}
            for name, cmd in cases.items()}
