"""``thermcap bench first-record``: the first recording on a machine against the next one.

A first boot, a new container or a fresh install starts with numba's cache empty. Each round
records ``duration`` seconds from the simulator in a fresh process with an empty cache (cold),
waits until the detector's kernels, compiled beside that recording, are in the cache, and
records again with it (warm, the anchor). Reported: each one's wall time for the command, the
frames analysed, and ``ls``'s duration against the frames' span. The goal (issue #61): cold
within the duration plus 3 s, at least 95% of frames analysed, ``ls`` showing the span.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_first_record", "print_lines"]


def _run(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "thermcap", *args], capture_output=True, text=True, env=env,
                          timeout=600)


def _record(root: Path, name: str, duration: float, size: tuple[int, int], env: dict[str, str]) -> dict[str, Any]:
    t = time.perf_counter()
    r = _run("record", "--root", str(root), "--session", name, "--duration", str(duration), "--width",
             str(size[0]), "--height", str(size[1]), "--json", env=env)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"thermcap record failed: {r.stderr[-500:]}")
    res = json.loads(r.stdout)
    listed = {s["id"]: s for s in json.loads(_run("ls", "--root", str(root), "--json", env=env).stdout)["sessions"]}
    info = json.loads(_run("info", str(DataRoot.of(root).session_dir(name)), "--json", env=env).stdout)
    frames = int(res["frames_written"])
    return {"wall_s": round(wall, 3), "frames": frames,
            "analysed": round((frames - int(res["analysis_skipped"])) / frames, 4) if frames else 0.0,
            "kernels": (res.get("analysis_runner") or {}).get("kernels"),
            "ls_duration_s": listed[name]["duration_s"], "span_s": info["duration_s"]}


def _cached(env: dict[str, str]) -> bool:
    code = "from thermcap.recorder.analysis import detector_kernels as k; print(k.cached())"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    return r.stdout.strip() == "True"


def bench_first_record(duration: float = 2.0, rounds: int = 3, size: tuple[int, int] = (640, 512),
                       compile_timeout_s: float = 600.0) -> dict[str, Any]:
    cold: list[dict[str, Any]] = []
    warm: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="thermcap-bench-first-") as tmp:
        for r in range(rounds):
            env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / f"numba-{r}")}
            root = Path(tmp) / f"root-{r}"
            cold.append(_record(root, "cold", duration, size, env))
            deadline = time.monotonic() + compile_timeout_s
            while not _cached(env):  # the compile outlives the recording: wait for its result
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the kernels were not in the cache {compile_timeout_s:g} s after the recording")
                time.sleep(2.0)  # each look is a Python process: it must not starve the compile
            warm.append(_record(root, "warm", duration, size, env))

    def med(rows: list[dict[str, Any]], key: str) -> float:
        return round(statistics.median(row[key] for row in rows), 3)

    cold_wall, warm_wall = med(cold, "wall_s"), med(warm, "wall_s")
    return {"duration_s": duration, "size": f"{size[0]}x{size[1]}", "rounds": rounds,
            "cold_wall_s": cold_wall, "warm_wall_s": warm_wall, "cold_vs_warm": round(cold_wall / warm_wall, 3),
            "cold_analysed": min(row["analysed"] for row in cold),
            "warm_analysed": min(row["analysed"] for row in warm),
            "cold_kernels": sorted({str(row["kernels"]) for row in cold}),
            "ls_off_span_s": max(abs(row["ls_duration_s"] - row["span_s"]) for row in cold + warm),
            "goal_met": cold_wall <= duration + 3.0 and min(row["analysed"] for row in cold) >= 0.95,
            "cold": cold, "warm": warm}


def print_lines(res: dict[str, Any]) -> list[str]:
    return [
        f"first recording, {res['size']}, {res['duration_s']:g} s, median of {res['rounds']}: "
        f"empty kernel cache {res['cold_wall_s']} s ({res['cold_analysed']:.1%} analysed, kernels "
        f"{'/'.join(res['cold_kernels'])}) vs warm {res['warm_wall_s']} s ({res['warm_analysed']:.1%}) "
        f"= {res['cold_vs_warm']}x",
        f"ls against the frames' span: at most {res['ls_off_span_s']} s apart; goal (cold <= duration + 3 s, "
        f">= 95% analysed): {'met' if res['goal_met'] else 'NOT met'}",
    ]
