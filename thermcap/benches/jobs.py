"""``thermcap bench jobs``: the same sessions archived as Dask tasks (one per segment, then a
finalize per session) on a LocalCluster of one worker and of two, in one run. Each worker process
is pinned to a core of its own, as a cluster of one-core machines: unpinned, one worker's task
already spreads its format threads over both of this host's cores, and the scaling would measure
nothing. The ratio is the scaling (2x is the limit on two cores). The per-core rate gives the
capacity model in the README: cores needed for N cameras recording H hours a day."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_jobs"]


def _pin_process(core: int) -> int:
    """Every thread of this worker process (and those it starts later) on one core."""
    for tid in os.listdir("/proc/self/task"):
        with contextlib.suppress(OSError):
            os.sched_setaffinity(int(tid), {core})
    return core


def bench_jobs(sessions: int = 1, seconds: float = 10.0, formats: tuple[str, ...] = ("png16", "tiff-lzw", "hdf5"),
               workdir: str | None = None, segment_s: float = 1.0, pin: bool = True) -> dict[str, Any]:
    from thermcap.api.db import make_engine, migrate
    from thermcap.api.jobs.dask_jobs import DaskJobs, TaskConfig
    from thermcap.api.jobs.worker import Worker
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource
    from thermcap.recorder.storage.segments import SegmentPolicy

    n = int(seconds * 60)
    out: dict[str, Any] = {"sessions": sessions, "seconds_each": seconds, "frames_each": n, "formats": list(formats),
                           "segment_s": segment_s, "one_core_per_worker": pin}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        pristine = Path(tmp) / "pristine"
        for k in range(sessions):
            Recorder(SimSource(width=640, height=512, frames=n, paced=False, seed=k), pristine, session_id=f"b{k}",
                     analysis=False, recover_leftovers=False, policy=SegmentPolicy(max_duration_s=segment_s)).run()
        from thermcap.recorder.storage.reader import session_segments

        out["segments_each"] = len(session_segments(DataRoot.of(pristine).session_dir("b0")))
        for workers in (1, 2):
            root = Path(tmp) / f"root{workers}"
            shutil.copytree(pristine, root)
            db = f"sqlite:///{Path(tmp) / f'index{workers}.sqlite'}"
            engine = make_engine(db)
            migrate(engine)
            jobs = DaskJobs(Worker(root, engine, formats=list(formats), log=lambda m: None),
                            TaskConfig(str(root), formats, db, None, False), local_workers=workers)
            if pin:  # one core per worker, as machines of one core each: a task's format threads share it
                for k, addr in enumerate(sorted(jobs.client.scheduler_info()["workers"])):
                    jobs.client.run(_pin_process, k % (os.cpu_count() or 1), workers=[addr])
            try:
                t = time.perf_counter()
                res = jobs.run_once()
                wall = time.perf_counter() - t
            finally:
                jobs.close()
            if len(res.archived) != sessions or res.failed:
                raise RuntimeError(f"the benchmark's sessions did not all archive: {res.failed}")
            out[f"wall_s_{workers}_worker"] = round(wall, 2)
            out[f"x_real_time_{workers}_worker"] = round(sessions * seconds / wall, 3)
    out["scaling_2_over_1"] = round(out["wall_s_1_worker"] / out["wall_s_2_worker"], 3)
    per_core = out["x_real_time_1_worker"]
    out["capacity"] = {"camera_hours_per_core_hour": per_core,
                       "cores_for_10_cameras_8h_a_day_in_24h": round(10 * 8 / (per_core * 24), 2),
                       "cores_for_100_cameras_8h_a_day_in_24h": round(100 * 8 / (per_core * 24), 2)}
    return out
