"""``thermcap bench live``: what two live viewers get, and what they cost the recorder.

A paced 640x512@60 recording is measured twice in the same run: alone (the anchor), then with
the live view at full rate and resolution and two viewers, each a separate process speaking
the Foxglove WebSocket protocol (the ``websockets`` package). Reported: frames/s each viewer
received, the recorder's drops (must stay 0), the live view's own drops, and the process CPU
with and without viewers.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from thermcap.benches.cameras import measure_recording
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.install_hint import install_command

__all__ = ["bench_live", "print_table"]

_VIEWER = r"""
import json, struct, sys, time
from websockets.sync.client import connect
url, seconds = sys.argv[1], float(sys.argv[2])
deadline = time.monotonic() + 30
while True:
    try:
        ws = connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], max_size=None)
        break
    except OSError:
        if time.monotonic() > deadline:
            raise
        time.sleep(0.05)
chan = None
while chan is None:
    m = json.loads(ws.recv())
    if m.get("op") == "advertise":
        chan = next((c["id"] for c in m["channels"] if c["topic"] == "/thermal/image"), None)
ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": chan}]}))
n = nbytes = 0
first = last = None
end = time.monotonic() + seconds
while time.monotonic() < end:
    try:
        m = ws.recv(timeout=max(0.01, end - time.monotonic()))
    except TimeoutError:
        break
    if isinstance(m, bytes) and m[0] == 1:
        now = time.monotonic()
        first = first or now
        last = now
        n += 1
        nbytes += len(m)
ws.close()
span = (last - first) if first and last and last > first else 0
print(json.dumps({"frames": n, "bytes": nbytes, "fps": round((n - 1) / span, 2) if span else 0.0}))
"""


def _sim() -> SimSource:
    return SimSource(width=640, height=512, fps=60.0, paced=True, seed=1)


def bench_live(seconds: float = 10.0, viewers: int = 2, live_fps: float = 60.0, live_width: int = 0,
               workdir: str | None = None) -> dict[str, Any]:
    try:
        import websockets  # noqa: F401  (the viewers need it)
    except ImportError as exc:
        raise RuntimeError("bench live needs the websockets package for its viewers "
                           f"({install_command('test')})") from exc
    from thermcap.recorder.live.branch import LiveBranch
    from thermcap.recorder.live.publisher import LiveOptions

    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        alone = measure_recording(_sim(), Path(tmp) / "alone", seconds)
        branch = LiveBranch(LiveOptions(port=0, max_fps=live_fps, max_width=live_width))
        procs: list[subprocess.Popen] = []

        def start_viewers(_rec: Any) -> Any:
            for _ in range(viewers):
                procs.append(subprocess.Popen([sys.executable, "-c", _VIEWER, branch.url, str(seconds - 1.0)],
                                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))

            def collect() -> list[dict[str, Any]]:
                out = []
                for p in procs:
                    stdout, stderr = p.communicate(timeout=60)
                    out.append(json.loads(stdout) if p.returncode == 0 else {"error": stderr.strip()[-300:]})
                return out
            return collect

        try:
            watched = measure_recording(_sim(), Path(tmp) / "live", seconds, live=branch, during=start_viewers)
        finally:
            branch.close()
    return {"anchor": alone, "with_viewers": watched, "viewers": watched.pop("during"),
            "cpu_with_viewers_vs_alone": round(watched["process_cpu_cores"] / (alone["process_cpu_cores"] or 1e-9), 2),
            "live_fps": live_fps, "live_width": live_width or 640}


def print_table(res: dict[str, Any]) -> str:
    a, w = res["anchor"], res["with_viewers"]
    lines = [f"recording 640x512@60 for {a['wall_s']} s, live view at {res['live_fps']:g} fps, "
             f"width {res['live_width']}",
             f"{'':22} {'process CPU':>11} {'recorder drops':>14}",
             f"{'no viewers (anchor)':22} {a['process_cpu_cores']:>11} {a['frames_dropped']:>14}",
             f"{str(len(res['viewers'])) + ' viewers':22} {w['process_cpu_cores']:>11} {w['frames_dropped']:>14}"]
    for i, v in enumerate(res["viewers"]):
        lines.append(f"  viewer {i}: " + (f"{v['frames']} frames, {v['fps']} frames/s, {v['bytes']:,} bytes"
                                          if "error" not in v else f"failed: {v['error']}"))
    lv = w["live"]
    lines.append(f"live view: {lv['published']} frames published, {lv['dropped']} dropped by the view, "
                 f"its thread {w['live_thread_cpu_cores']} cores")
    lines.append(f"process CPU with viewers vs without: {res['cpu_with_viewers_vs_alone']}x")
    return "\n".join(lines)
