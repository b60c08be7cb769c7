"""One timed run of one writer (the recorder or foxglove-sdk's), in a process of its own.

Why a process each: run in one process, one after the other, a recorder run that came right
after an SDK run cost 7-35% more CPU than one after another recorder run (2.51-3.15 against
2.31-2.40 ms a frame at 640x512, in the same bench), while the SDK's runs did not move. A
user's recorder never shares its process with the SDK, so neither writer is measured in the
other's leftovers. Each process renders the same simulated frames, warms its writer up
untimed, and prints one JSON line: ``{"cpu_s_per_frame", "wall_s", "bytes"}``.

``python -m recorder.bench.writer_run recorder|sdk WIDTHxHEIGHT FRAMES LEVEL WORKDIR``
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

__all__ = ["WriterRun", "run_isolated"]

WRITERS = ("recorder", "sdk")


@dataclass(frozen=True)
class WriterRun:
    cpu_s_per_frame: float
    wall_s: float
    bytes: int


def run_isolated(writer: str, width: int, height: int, frames: int, level: int, workdir: Path) -> WriterRun:
    """Run ``writer`` once in a fresh interpreter; its files are removed before it returns."""
    if writer not in WRITERS:
        raise ValueError(f"writer must be one of {WRITERS}, got {writer!r}")
    cmd = [sys.executable, "-m", "recorder.bench.writer_run", writer, f"{width}x{height}", str(frames), str(level),
           str(workdir)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"bench {writer} run failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return WriterRun(float(out["cpu_s_per_frame"]), float(out["wall_s"]), int(out["bytes"]))


def _main(argv: list[str]) -> int:
    from recorder.bench.record import _foxglove_sdk, _record_once
    from recorder.capture.sources.sim import SimSource
    from recorder.storage.segments import auto_compression

    writer, size, frames, level, workdir = argv
    width, height = (int(v) for v in size.split("x"))
    n, lvl, base = int(frames), int(level), Path(workdir)
    base.mkdir(parents=True, exist_ok=True)
    sim = SimSource(width=width, height=height, frames=60, paced=False, seed=1)
    rendered = list(sim.frames())
    comp, _ = auto_compression(width, height, 60.0)
    for warm, count in ((True, min(n, 120)), (False, n)):
        if writer == "sdk":
            path = base / "sdk.mcap"
            cpu, wall, size_b = _foxglove_sdk(rendered, count, path, lvl)
            path.unlink(missing_ok=True)
        else:
            root = base / "recorder"
            res, wall, cpu = _record_once(sim, rendered, count, comp, lvl, False, 60.0, root)
            size_b = sum(s["bytes"] for s in res.segments)
            shutil.rmtree(root, ignore_errors=True)
        if not warm:
            print(json.dumps({"cpu_s_per_frame": cpu, "wall_s": wall, "bytes": size_b}))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
