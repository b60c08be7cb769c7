"""``thermcap bench gige``: what a GigE Vision frame costs the recorder, beside a raw pipe's.

Both record 640x512 Mono16 at 60 fps for the same time, in the same run, without analysis: the
GigE source from a camera through Aravis (by default Aravis's fake camera, started in a network
namespace that holds only loopback, since discovery broadcasts), and the anchor, the same frames
as raw Gray16 through a pipe from ffmpeg's test pattern (``exec:``). The figure is the capture
thread's CPU per frame (Aravis's own stream thread is in the process figure). On loopback the
kernel's receive work is charged to the sender, so a real network costs the recorder more.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from thermcap.benches.cameras import measure_recording

__all__ = ["INSIDE_ENV", "bench_gige", "print_lines"]

W, H, FPS = 640, 512, 60.0
FAKE = "arv-fake-gv-camera-0.8"
INSIDE_ENV = "THERMCAP_BENCH_LOOPBACK_NAMESPACE"  # set when this run is inside its namespace


def _per_frame(run: dict[str, Any], label: str) -> dict[str, Any]:
    cam = run["cameras"][label]
    frames = max(cam["captured"], 1)
    return {"frames": cam["captured"], "dropped": cam["dropped"],
            "capture_us_per_frame": round(cam["cpu_cores"] * run["wall_s"] / frames * 1e6, 1),
            "process_us_per_frame": round(run["process_cpu_cores"] * run["wall_s"] / frames * 1e6, 1),
            "fps": round(cam["captured"] / run["wall_s"], 1)}


def bench_gige(seconds: float, camera: str, workdir: str | None = None) -> dict[str, Any]:
    from thermcap.recorder.capture.sources.command import CommandSource
    from thermcap.recorder.capture.sources.gige import GigEOptions, GigESource

    out: dict[str, Any] = {"size": f"{W}x{H}@{FPS:g}", "seconds": seconds, "camera": camera}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        gige = GigESource(GigEOptions(camera=camera, width=W, height=H, fps=FPS))
        run = measure_recording({"gige": gige}, Path(tmp) / "gige", seconds, analysis=False)
        out["gige"] = {**_per_frame(run, "gige"), "incomplete": gige.health()["incomplete_frames"]}
        if shutil.which("ffmpeg"):
            pipe = CommandSource(f"ffmpeg -v error -re -f lavfi -i testsrc=size={W}x{H}:rate={FPS:g} "
                                 f"-pix_fmt gray16le -f rawvideo -", width=W, height=H, fps=FPS)
            out["raw_pipe"] = _per_frame(measure_recording({"pipe": pipe}, Path(tmp) / "pipe", seconds,
                                                           analysis=False), "pipe")
            out["gige_vs_raw_pipe"] = round(out["gige"]["capture_us_per_frame"]
                                            / max(out["raw_pipe"]["capture_us_per_frame"], 1e-3), 2)
        else:
            out["raw_pipe"] = None
            out["note"] = "no ffmpeg: the raw pipe anchor did not run (apt: ffmpeg)"
    return out


def run_in_loopback_namespace(argv: list[str]) -> int:
    """This command again inside ``unshare -n`` with Aravis's fake camera on its loopback."""
    if shutil.which("unshare") is None or shutil.which(FAKE) is None:
        raise RuntimeError(f"the fake camera needs unshare and {FAKE} (apt: aravis-tools); or name a camera "
                           f"with --camera")
    script = (f'ip link set lo up || exit 1; {FAKE} -i lo >/dev/null 2>&1 & camera=$!; '
              f'until ss -Huln "sport = :3956" | grep -q 3956; do kill -0 $camera || exit 1; sleep 0.05; done; '
              f'"$@"; code=$?; kill $camera; exit $code')
    env = {**os.environ, INSIDE_ENV: "1"}
    return subprocess.run(["unshare", "-n", "bash", "-c", script, "bench", sys.executable, "-m", "thermcap",
                           *argv], env=env, check=False).returncode


def print_lines(res: dict[str, Any]) -> list[str]:
    g = res["gige"]
    lines = [f"gige {res['camera']} {res['size']}: {g['capture_us_per_frame']} us a frame on the capture thread "
             f"({g['process_us_per_frame']} for the process), {g['frames']} frames at {g['fps']} fps, "
             f"{g['dropped']} dropped, {g['incomplete']} incomplete"]
    p = res.get("raw_pipe")
    if p:
        lines.append(f"raw pipe (ffmpeg) {res['size']}: {p['capture_us_per_frame']} us a frame on the capture "
                     f"thread ({p['process_us_per_frame']} for the process), {p['frames']} frames at {p['fps']} fps")
        lines.append(f"gige vs raw pipe, capture CPU per frame: {res['gige_vs_raw_pipe']}x")
    else:
        lines.append(res.get("note", ""))
    return lines


