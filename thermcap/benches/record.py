"""``thermcap bench record``: the recorder's write path against the cheapest real writer.

Frames come from memory (simulated once, before timing) and go through the real path: sidecar
built and validated, CDR image encoded, chunked MCAP with zstd on the compression pool, fsynced
segments. The baseline, measured in the same run on the same frames, is the cheapest writer a
user could write instead: each frame zstd-compressed (same level, one thread) and appended to
a file. Ratios against it, not absolute timings, are what to compare across machines.
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import zstandard

from thermcap.benches.writer_run import MemorySource, WriterRun, record_once, run_isolated
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.base import CapturedFrame
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import auto_compression
from thermcap.recorder.storage.writer import Compression

__all__ = ["MemorySource", "bench_record", "print_table", "run_soak"]


def _baseline(frames: list[CapturedFrame], n: int, path: Path, level: int) -> float:
    comp = zstandard.ZstdCompressor(level=level)
    t = time.perf_counter()
    with open(path, "wb") as f:
        for i in range(n):
            f.write(comp.compress(frames[i % len(frames)].pixels.tobytes()))
        f.flush()
        os.fsync(f.fileno())
    return n / (time.perf_counter() - t)


def _against_sdk(width: int, height: int, n: int, base: Path, level: int,
                 rounds: int) -> tuple[WriterRun, WriterRun, list[float], list[float]]:
    """The recorder and the SDK ``rounds`` times each in alternating order (R S S R R S ...), every
    run in a process of its own (``writer_run``) with its files removed after it: whichever runs
    second meets a different page cache, and in one process a recorder run after an SDK run
    cost up to a third more. Each process primes the page cache for its output first
    (``page_cache``). Returns each writer's median run by CPU (of an even number, the upper of
    the two middle runs), each round's ratio, and what priming cost each run, untimed."""
    ours: list[WriterRun] = []
    theirs: list[WriterRun] = []
    order = "".join("RS" if i % 2 == 0 else "SR" for i in range(rounds))
    for k, who in enumerate(order):
        run = run_isolated("recorder" if who == "R" else "sdk", width, height, n, level, base / f"run-{k}")
        (ours if who == "R" else theirs).append(run)

    def median(runs: list[WriterRun]) -> WriterRun:
        return sorted(runs, key=lambda r: r.cpu_s_per_frame)[len(runs) // 2]

    pairs = [round(a.cpu_s_per_frame / b.cpu_s_per_frame, 3) for a, b in zip(ours, theirs, strict=True)]
    return median(ours), median(theirs), pairs, [round(r.primed_cpu_s, 2) for r in ours + theirs]


def bench_record(sizes: list[tuple[int, int]], n_frames: int = 600, *, workdir: str | None = None,
                 progress: bool = True, fps: float = 60.0,
                 compressions: tuple[str, ...] = ("auto", "auto+analysis", "lz4"),
                 sdk_rounds: int = 5) -> list[dict[str, Any]]:
    """One row per frame size and mode: "auto" is ``thermcap record``'s compression with analysis off,
    "auto+analysis" the same with the detector running beside it (at the camera's 60 fps). Where
    the SDK anchors a row, both writers run ``sdk_rounds`` times in alternating order and the row
    gives each one's median CPU."""
    rows = []
    base = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="thermcap-bench-"))
    base.mkdir(parents=True, exist_ok=True)
    try:
        for (width, height), name in [(wh, c) for wh in sizes for c in compressions]:
            sim = SimSource(width=width, height=height, frames=60, paced=False, seed=1)
            rendered = list(sim.frames())
            analysis = name.endswith("+analysis")
            if name.startswith("auto"):
                comp, level = auto_compression(width, height, fps)
            else:
                comp, level = Compression(name), (1 if name == "zstd" else 0)
            if progress:
                print(f"  {width}x{height} {name} ({comp.value}-{level}): {n_frames} frames ...", flush=True)
            baseline_fps = _baseline(rendered, n_frames, base / f"baseline-{width}.zst", 1)
            root = base / f"root-{width}-{name}"
            # Warm-up, not timed: what a process does once (imports, compiled message encoders and
            # validators, the detector's first call) must not be charged to per-frame CPU, as the
            # SDK's import and context are not.
            warm = base / f"warm-{width}-{name}"
            record_once(sim, rendered, min(n_frames, 120), comp, level, analysis, fps, warm)
            shutil.rmtree(warm, ignore_errors=True)
            res, dt, cpu_per_frame, _ = record_once(sim, rendered, n_frames, comp, level, analysis, fps, root)
            sdk = ours = None
            if comp is Compression.ZSTD and not analysis:  # the anchor: foxglove-sdk's writer, same frames
                ours, sdk, pairs, primed = _against_sdk(width, height, n_frames, base, level, sdk_rounds)
                cpu_per_frame = ours.cpu_s_per_frame
            rec_fps = n_frames / dt
            size = sum(s["bytes"] for s in res.segments)
            frame_mb = width * height * 2 / 1e6
            rows.append({
                "width": width, "height": height, "frames": n_frames, "fps": round(rec_fps, 1),
                "mb_per_s": round(rec_fps * frame_mb, 1), "x_realtime": round(rec_fps / fps, 2),
                "baseline_fps": round(baseline_fps, 1), "x_baseline": round(rec_fps / baseline_fps, 2),
                "ratio": round(n_frames * width * height * 2 / size, 3), "mode": name,
                "compression": f"{comp.value}-{level}",
                "cpus": os.cpu_count(),
                "cpu_ms_per_frame": round(cpu_per_frame * 1e3, 3),
                "cores_at_60fps": round(cpu_per_frame * fps, 3),
                **({"sdk_cpu_ms_per_frame": round(sdk.cpu_s_per_frame * 1e3, 3),
                    "sdk_fps": round(n_frames / sdk.wall_s, 1),
                    "sdk_ratio": round(n_frames * width * height * 2 / sdk.bytes, 3),
                    "cpu_vs_sdk": round(cpu_per_frame / sdk.cpu_s_per_frame, 3), "sdk_rounds": sdk_rounds,
                    "cpu_vs_sdk_each_round": pairs, "cpu_vs_sdk_rounds_median": statistics.median(pairs),
                    # the kernel's part of each median run, and the untimed priming of each run
                    "sys_ms_per_frame": round(ours.sys_s_per_frame * 1e3, 3),
                    "sdk_sys_ms_per_frame": round(sdk.sys_s_per_frame * 1e3, 3),
                    "primed_cpu_s_each_run": primed} if sdk and ours else {}),
            })
            shutil.rmtree(root, ignore_errors=True)
    finally:
        if workdir is None:
            shutil.rmtree(base, ignore_errors=True)
    return rows


def run_soak(seconds: float, *, workdir: str | None = None, width: int = 640, height: int = 512,
             fps: float = 60.0) -> dict[str, Any]:
    """Paced simulator for ``seconds``: drops, p99 write latency, and RSS growth."""
    import resource

    base = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="thermcap-soak-"))
    rss: list[tuple[float, float]] = []
    t0 = time.monotonic()

    def sample(_rec: Any) -> None:
        now = time.monotonic() - t0
        if not rss or now - rss[-1][0] >= 10.0:
            rss.append((now, _rss_mb()))

    try:
        sim = SimSource(width=width, height=height, fps=fps, duration_s=seconds, paced=True, seed=2)
        res = Recorder(sim, base, recover_leftovers=False).run(progress=sample)
        return {
            "seconds": seconds, "width": width, "height": height, "fps": fps,
            "frames_captured": res.frames_captured, "frames_written": res.frames_written,
            "frames_dropped": res.frames_dropped, "write_latency_p50_ms": res.write_latency_ms["p50"],
            "write_latency_p99_ms": res.write_latency_ms["p99"], "write_latency_max_ms": res.write_latency_ms["max"],
            "rss_start_mb": round(rss[0][1], 1) if rss else None,
            "rss_end_mb": round(rss[-1][1], 1) if rss else None,
            # After the first minute (allocator arenas, caches and the first segment warmed up):
            "rss_growth_after_60s_mb": round(rss[-1][1] - next((m for t, m in rss if t >= 60), rss[-1][1]),
                                             1) if rss else None,
            "rss_mb_every_10s": [round(m, 1) for _, m in rss],
            "rss_peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "segments": len(res.segments), "ok": res.ok,
        }
    finally:
        if workdir is None:
            shutil.rmtree(base, ignore_errors=True)


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def print_table(rows: list[dict[str, Any]]) -> str:
    head = (f"{'size':>10} {'mode':>13} {'chunks':>7} {'fps':>7} {'MB/s':>7} {'x real':>7} {'base fps':>9} "
            f"{'x base':>7} {'ratio':>6} {'CPU ms/f':>9} {'cores@60':>8} {'SDK ms/f':>9} {'vs SDK':>7}")
    lines = [head, "(base = each frame zstd-1 compressed and appended to a file, one thread; SDK = foxglove-sdk's "
                   "MCAP writer, RawImage + JSON sidecar and source messages, same zstd level; recorder and SDK "
                   "medians of alternating runs, each in a process of its own; CPU of all threads)"]
    for r in rows:
        lines.append(f"{r['width']:>5}x{r['height']:<4} {r['mode']:>13} {r['compression']:>7} {r['fps']:>7} "
                     f"{r['mb_per_s']:>7} {r['x_realtime']:>7} {r['baseline_fps']:>9} {r['x_baseline']:>7} "
                     f"{r['ratio']:>6} {r['cpu_ms_per_frame']:>9} {r['cores_at_60fps']:>8} "
                     f"{r.get('sdk_cpu_ms_per_frame', '-'):>9} {r.get('cpu_vs_sdk', '-'):>7}")
    return "\n".join(lines)
