"""``thermcap bench cameras``: several cameras in one process, drops and CPU per camera.

The anchor is one 640x512@60 camera recorded alone in the same run; then the issue's mix, two
640x512@60 and one 320x256@30, on one clock. Each camera's own CPU is its capture thread (from
/proc) and its detector (a child process, which reports its own CPU; a thread where none
starts); the writer, chunk compression and fsync are shared and reported as such. The process
figure includes the detector processes.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from thermcap.benches.cpu import ThreadCpu, process_cpu_s
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.base import FrameSource
from thermcap.recorder.capture.sources.sim import SimSource

__all__ = ["MIX", "bench_cameras", "measure_recording", "print_table"]

MIX = {"front": (640, 512, 60.0), "rear": (640, 512, 60.0), "aux": (320, 256, 30.0)}


def measure_recording(sources: FrameSource | Mapping[str, FrameSource], root: Path, seconds: float,
                      live: Any = None, during: Any = None, analysis: bool = True) -> dict[str, Any]:
    """Record for ``seconds`` with CPU sampled per thread; ``during(rec)`` runs beside it."""
    rec = Recorder(sources, root, live=live, recover_leftovers=False, analysis=analysis)
    cpu = ThreadCpu()
    cpu.start()

    def register() -> None:
        for f in rec.feeds:
            cpu.watch.update(f.thread_ids.values())
            if f.runner is not None:
                cpu.watch.update(f.runner.native_ids.values())
        if rec.writer_thread_id:
            cpu.watch.add(rec.writer_thread_id)
        if live is not None and live.thread_id:
            cpu.watch.add(live.thread_id)

    c0, t0 = process_cpu_s(), time.monotonic()
    extra = during(rec) if during is not None else None
    res = rec.run(duration_s=seconds, progress=lambda _r: register())
    wall, used = time.monotonic() - t0, process_cpu_s() - c0
    cpu.stop()
    cameras = {}
    children = 0.0  # a detector in a child process: its CPU is not in this process's
    for f in rec.feeds:
        own = sum(cpu.of(t) for t in f.thread_ids.values())
        if f.runner is not None:
            own += sum(cpu.of(t) for t in f.runner.native_ids.values())
            if f.runner.kind == "process":
                own += f.runner.cpu_s
                children += f.runner.cpu_s
        sensor = f.source.sensor
        cameras[f.label] = {"size": f"{sensor.width}x{sensor.height}@{sensor.frame_rate_hz:g}",
                            "captured": f.captured, "written": f.written,
                            "dropped": res.dropped.get(f.topics.image, 0),
                            "analysis_skipped": f.analysis_skipped,
                            "cpu_cores": round(own / wall, 3)}
    out = {"wall_s": round(wall, 2), "process_cpu_cores": round((used + children) / wall, 3),
           "detector_process_cpu_cores": round(children / wall, 3),
           "writer_cpu_cores": round(cpu.of(rec.writer_thread_id) / wall, 3),
           "frames_dropped": res.frames_dropped, "cameras": cameras, "error": res.error}
    if live is not None:
        out["live_thread_cpu_cores"] = round(cpu.of(live.thread_id) / wall, 3)
        out["live"] = live.snapshot()
    if extra is not None:
        out["during"] = extra() if callable(extra) else extra
    return out


def _sim(w: int, h: int, fps: float, seed: int) -> SimSource:
    return SimSource(width=w, height=h, fps=fps, paced=True, seed=seed)


def bench_cameras(seconds: float = 10.0, workdir: str | None = None) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        alone = measure_recording({"front": _sim(640, 512, 60.0, 1)}, Path(tmp) / "alone", seconds)
        mix = measure_recording({n: _sim(w, h, fps, i) for i, (n, (w, h, fps)) in enumerate(MIX.items())},
                                Path(tmp) / "mix", seconds)
    anchor = alone["cameras"]["front"]["cpu_cores"] or 1e-9
    for cam in mix["cameras"].values():
        cam["cpu_vs_alone"] = round(cam["cpu_cores"] / anchor, 2)
    return {"anchor": alone, "mix": mix,
            "process_cpu_vs_alone": round(mix["process_cpu_cores"] / (alone["process_cpu_cores"] or 1e-9), 2)}


def print_table(res: dict[str, Any]) -> str:
    lines = [f"{'run':8} {'camera':7} {'size':14} {'captured':>9} {'written':>8} {'dropped':>8} "
             f"{'not analysed':>12} {'CPU cores':>9} {'vs alone':>8}"]
    for run in ("anchor", "mix"):
        for name, c in res[run]["cameras"].items():
            lines.append(f"{run:8} {name:7} {c['size']:14} {c['captured']:9} {c['written']:8} {c['dropped']:8} "
                         f"{c['analysis_skipped']:12} {c['cpu_cores']:9} {c.get('cpu_vs_alone', 1.0):8}")
        r = res[run]
        lines.append(f"{run:8} process: {r['process_cpu_cores']} cores (writer thread {r['writer_cpu_cores']}), "
                     f"{r['frames_dropped']} frames dropped over {r['wall_s']} s")
    lines.append(f"process CPU, mix vs one camera alone: {res['process_cpu_vs_alone']}x")
    return "\n".join(lines)
