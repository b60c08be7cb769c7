"""One timed run of one writer: the recorder (``record_once``, frames replayed from memory by
``MemorySource``) or foxglove-sdk's MCAP writer (``sdk_once``), here or, through
``run_isolated``, in a process of its own.

Why a process each when they are compared: run in one process, one after the other, a recorder
run that came right after an SDK run cost 7-35% more CPU than one after another recorder run
(2.51-3.15 against 2.31-2.40 ms a frame at 640x512, in the same bench), while the SDK's runs
did not move. A user's recorder never shares its process with the SDK, so neither writer is
measured in the other's leftovers. Each process renders the same simulated frames, warms its
writer up untimed, primes the page cache for its output (``page_cache``: on this project's
virtual machines, pages the host took back cost a timed run up to 0.1 ms a frame of kernel CPU,
by chance), and prints one JSON line: ``{"cpu_s_per_frame", "sys_s_per_frame", "wall_s",
"bytes", "primed_cpu_s"}``.

``python -m recorder.bench.writer_run recorder|sdk WIDTHxHEIGHT FRAMES LEVEL WORKDIR``
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from thermcap.benches.cpu import process_cpu_split
from thermcap.benches.page_cache import prime
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy, auto_compression
from thermcap.recorder.storage.writer import Compression

__all__ = ["MemorySource", "WriterRun", "record_once", "run_isolated", "sdk_once"]

WRITERS = ("recorder", "sdk")


class MemorySource(FrameSource):
    """Replays pre-rendered frames (with their sidecar blocks) as fast as the recorder takes them."""

    name = "memory"

    def __init__(self, template: SimSource, frames: list[CapturedFrame], count: int) -> None:
        self.sensor = template.sensor
        self.model = template.model
        self.bad_pixel_map = template.bad_pixel_map
        self.extra_topics = template.extra_topics  # type: ignore[misc]  # mirrors its template's topics
        self._frames = frames
        self._count = count

    def frames(self):
        t0 = time.time_ns()
        for i in range(self._count):
            f = self._frames[i % len(self._frames)]
            yield CapturedFrame(index=i, timestamp_ns=t0 + int(i * 1e9 / 60), pixels=f.pixels,
                                capture_mono_ns=time.monotonic_ns(), sidecar=f.sidecar, messages=f.messages)


def sdk_once(frames: list[CapturedFrame], n: int, path: Path, level: int) -> tuple[float, float, float, int]:
    """The same frames through foxglove-sdk's MCAP writer (Rust): each image as a RawImage
    (mono16), each sidecar and each of the frame's other messages (the source's, e.g. the
    simulator's ground truth) as JSON, zstd at the same level. The JSON is serialised inside the
    timed loop, as a user of the SDK would have to: the recorder is timed serialising its own.
    (CPU s per frame, its kernel part, wall s, bytes.)"""
    import foxglove
    from foxglove.channels import RawImageChannel
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions
    from foxglove.messages import RawImage, Timestamp

    ctx = foxglove.Context()
    opts = MCAPWriteOptions(compression=MCAPCompression.Zstd, compression_level=level, chunk_size=4 << 20)
    cpu, t = process_cpu_split(), time.perf_counter()
    writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=ctx, writer_options=opts)
    images = RawImageChannel("/thermal/image", context=ctx)
    meta = foxglove.Channel("/thermal/metadata", message_encoding="json", context=ctx)
    others: dict[str, foxglove.Channel] = {}
    t0 = time.time_ns()
    for i in range(n):
        f = frames[i % len(frames)]
        ts = t0 + int(i * 1e9 / 60)
        h, w = f.pixels.shape
        images.log(RawImage(timestamp=Timestamp.from_epoch_secs(ts / 1e9), frame_id="thermal", width=w, height=h,
                            encoding="mono16", step=w * 2, data=f.pixels.tobytes()), log_time=ts)
        meta.log(json.dumps(f.sidecar, separators=(",", ":")).encode(), log_time=ts)
        for topic, doc in f.messages:
            channel = others.get(topic)
            if channel is None:
                channel = others[topic] = foxglove.Channel(topic, message_encoding="json", context=ctx)
            channel.log(json.dumps(doc, separators=(",", ":")).encode(), log_time=ts)
    writer.close()
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())
    done = process_cpu_split()
    return (done[0] - cpu[0]) / n, (done[1] - cpu[1]) / n, time.perf_counter() - t, path.stat().st_size


def record_once(sim: SimSource, rendered: list[CapturedFrame], n_frames: int, comp: Compression, level: int,
                 analysis: bool, fps: float, where: Path) -> tuple[Any, float, float, float]:
    """One recording of the frames into ``where``: (result, wall s, CPU s a frame, its kernel part)."""
    rec = Recorder(MemorySource(sim, rendered, n_frames), where, queue_frames=max(120, n_frames),
                   policy=SegmentPolicy(compression=comp, compression_level=level),
                   recover_leftovers=False, analysis=analysis, analysis_max_fps=fps)
    cpu = process_cpu_split()
    t = time.perf_counter()
    res = rec.run()
    dt = time.perf_counter() - t
    # +analysis: the detector is capped at the camera's rate while the frames come as fast as the
    # recorder takes them, so most frames are (rightly) marked skipped: that is no failure
    if res.error is not None or res.dropped or res.frames_written != n_frames:
        raise RuntimeError(f"bench recording failed: {res.error or res.dropped or res.frames_written}")
    done = process_cpu_split()
    runner = res.analysis_runner or {}
    child = float(runner.get("cpu_s") or 0.0) if runner.get("runner") == "process" else 0.0  # not in ours
    return res, dt, (done[0] - cpu[0] + child) / n_frames, (done[1] - cpu[1]) / n_frames


@dataclass(frozen=True)
class WriterRun:
    cpu_s_per_frame: float  #: user and kernel
    wall_s: float
    bytes: int
    sys_s_per_frame: float = 0.0  #: the kernel's part
    primed_cpu_s: float = 0.0  #: what priming the page cache cost, untimed (``page_cache``)


def run_isolated(writer: str, width: int, height: int, frames: int, level: int, workdir: Path) -> WriterRun:
    """Run ``writer`` once in a fresh interpreter; its files are removed before it returns."""
    if writer not in WRITERS:
        raise ValueError(f"writer must be one of {WRITERS}, got {writer!r}")
    cmd = [sys.executable, "-m", "thermcap.benches.writer_run", writer, f"{width}x{height}", str(frames),
           str(level), str(workdir)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"bench {writer} run failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return WriterRun(float(out["cpu_s_per_frame"]), float(out["wall_s"]), int(out["bytes"]),
                     float(out["sys_s_per_frame"]), float(out["primed_cpu_s"]))


def _main(argv: list[str]) -> int:
    writer, size, frames, level, workdir = argv
    width, height = (int(v) for v in size.split("x"))
    n, lvl, base = int(frames), int(level), Path(workdir)
    base.mkdir(parents=True, exist_ok=True)
    sim = SimSource(width=width, height=height, frames=60, paced=False, seed=1)
    rendered = list(sim.frames())
    comp, _ = auto_compression(width, height, 60.0)
    warm_n, warm_bytes, primed = min(n, 120), 0, 0.0
    for warm, count in ((True, warm_n), (False, n)):
        if not warm:  # the run's output size, from the warm-up's: see page_cache
            primed = prime(base, int(warm_bytes * count / warm_n * 1.1))
        if writer == "sdk":
            path = base / "sdk.mcap"
            cpu, sys_s, wall, size_b = sdk_once(rendered, count, path, lvl)
            path.unlink(missing_ok=True)
        else:
            root = base / "recorder"
            res, wall, cpu, sys_s = record_once(sim, rendered, count, comp, lvl, False, 60.0, root)
            size_b = sum(s["bytes"] for s in res.segments)
            shutil.rmtree(root, ignore_errors=True)
        if warm:
            warm_bytes = size_b
        else:
            print(json.dumps({"cpu_s_per_frame": cpu, "sys_s_per_frame": sys_s, "wall_s": wall,
                              "bytes": size_b, "primed_cpu_s": primed}))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
