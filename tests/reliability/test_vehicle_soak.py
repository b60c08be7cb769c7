"""The vehicle journey as a soak: a GigE Vision camera (Aravis's fake, 640x512 Mono16 at 60 fps,
in a loopback-only network namespace) into a ring on a small budget, ``sync --watch`` to a folder
depot beside it, a mark every few seconds through ``ctl mark``, the camera killed and started
again, the recorder killed with SIGKILL and started again, then ``sync-confirm`` on the depot.

At the end, every frame is accounted for:
- each frame in the depot is bit-exact (the fake's ramp, from its device frame id);
- each session's frames are in the depot or in a segment the ring evicted (``eviction.log``,
  with its frame count): written = in the depot + evicted;
- the camera's gap is a ``source_gap`` event, with the frames it missed;
- every mark whose answer said its window is kept has every frame of that window in the depot
  (no evicted segment overlaps it, and frames follow each other in it);
- ``sync --watch`` never exited until asked, and exits 0 then;
- the recorder's memory stays flat.

The short form (the default, about a minute of recording) runs in CI; ``THERMCAP_SOAK_S=3600``
is the long one, with the camera killed every few minutes.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from tests.conftest import wait_for
from tests.support.netns import LoopbackNamespace, loopback_namespace
from tests.system.test_gige_camera import FAKE, GVCP_PORT, _skip
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.ring import read_eviction_log

pytestmark = [pytest.mark.slow, pytest.mark.skipif(_skip is not None, reason=_skip or "")]

W, H, FPS = 640, 512, 60
TOKEN = "vehicle-soak-token-0123456789abcdef"
SOAK_S = float(os.environ.get("THERMCAP_SOAK_S", "60"))
MARK_EVERY_S = 8.0
# An hour at 39 MB/s is 140 GB in the depot: the long form compresses (the fake's ramp packs
# well), the short form keeps the uncompressed path the short budget was sized for.
COMPRESSION = os.environ.get("THERMCAP_SOAK_COMPRESSION", "none" if SOAK_S <= 600 else "zstd")
CAMERA_KILL_EVERY_S = min(max(SOAK_S / 3, 20.0), 300.0)  # every five minutes in the long form


def _ramp(block_id: int) -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W]
    return ((block_id + x + y) % 65535).astype(">u2").view("<u2")


def _rss_kib(pid: int) -> int:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    m = re.search(r"VmRSS:\s+(\d+)", text)
    return int(m.group(1)) if m else 0


class Vehicle:
    """The processes of one vehicle, each inside the namespace."""

    def __init__(self, ns: LoopbackNamespace, root: Path, depot: Path) -> None:
        self.ns, self.root, self.depot = ns, root, depot
        self.env = ["env", f"THERMCAP_CONTROL_TOKEN={TOKEN}"]
        self.camera: subprocess.Popen | None = None
        self.recorder: subprocess.Popen | None = None
        self.session = ""
        self.marks: list[dict] = []
        self.logs = root.parent / "logs"  # each process's output, kept for a failure's message
        self.logs.mkdir(exist_ok=True)
        self.cameras_started = 0

    def start_camera(self) -> None:
        self.cameras_started += 1
        log = open(self.logs / f"camera-{self.cameras_started}.log", "wb")  # noqa: SIM115 - the process holds it
        self.camera = self.ns.popen([FAKE, "-i", "lo"], stdout=log, stderr=subprocess.STDOUT)
        assert wait_for(lambda: self.ns.udp_port_open(GVCP_PORT) or self.camera.poll() is not None, 60)
        assert self.camera.poll() is None, f"the fake camera exited at start: {self.tail('camera')}"

    def tail(self, what: str, n: int = 3000) -> str:
        """The end of the latest log of ``what`` ("camera", "recorder"): why a wait timed out."""
        logs = sorted(self.logs.glob(f"{what}-*.log"), key=lambda p: p.stat().st_mtime)
        return logs[-1].read_bytes()[-n:].decode(errors="replace") if logs else "(no log)"

    def kill_camera(self) -> None:
        assert self.camera is not None
        self.camera.send_signal(signal.SIGKILL)
        self.camera.wait(timeout=30)

    def start_recorder(self, session: str) -> None:
        self.session = session
        # 640x512 at 60 fps uncompressed: 39 MB/s into a 200 MB ring, so it evicts every few seconds
        self.recorder = self.ns.popen(
            [*self.env, sys.executable, "-m", "thermcap", "record", "--root", str(self.root), "--session", session,
             "--source", "gige:127.0.0.1", "--width", str(W), "--height", str(H), "--fps", str(FPS),
             "--no-analysis", "--compression", COMPRESSION, "--segment-duration", "0.5", "--ring", "--max-disk", "200M",
             "--max-protected", "100M", "--pre", "0.5", "--post", "0.5", "--control", "--json"],
            stdout=subprocess.PIPE, stderr=open(self.logs / f"recorder-{session}.log", "wb"), text=True)  # noqa: SIM115
        assert wait_for(lambda: self.status().get("frames_written", 0) > 0 or self.recorder.poll() is not None, 120)
        assert self.recorder.poll() is None, self.tail("recorder")

    def ctl(self, *args: str) -> dict:
        r = self.ns.run([*self.env, sys.executable, "-m", "thermcap", "ctl", *args, "--root", str(self.root),
                         "--session", self.session, "--json"], capture_output=True, text=True, timeout=60)
        return json.loads(r.stdout) if r.returncode == 0 and r.stdout.strip() else {}

    def status(self) -> dict:
        return self.ctl("status")

    def mark(self, note: str) -> None:
        answer = self.ctl("mark", "--note", note)
        assert answer, "ctl mark gave no answer"
        self.marks.append({"session": self.session, "note": note, "answer": answer})


class DepotFrame(NamedTuple):
    log_time: int
    device_frame_id: int
    segment: str


def _frames_in_depot(depot: Path, session: str) -> list[DepotFrame]:
    """Each frame in the depot checked bit-exact against the fake's ramp as it streams past
    (an hour's pixels do not fit in memory), keeping only what the accounting needs."""
    kept: list[DepotFrame] = []
    for f in iter_session_frames(depot / "sessions" / session):
        fid = f.sidecar_dict()["capture"]["device_frame_id"]
        assert np.array_equal(f.pixels, _ramp(fid)), (session, f.index)
        kept.append(DepotFrame(f.log_time, fid, str(f.segment)))
    return kept


def test_a_vehicle_ships_every_frame_or_names_why(tmp_path):
    root, depot = tmp_path / "vehicle", tmp_path / "depot"
    root.mkdir()
    depot.mkdir()
    rss: list[int] = []
    sync_rss: list[int] = []  # sync's too: its journal is the part of it that grows with the hour
    with loopback_namespace() as ns:
        v = Vehicle(ns, root, depot)
        v.start_camera()
        # its output to a file: a pipe nobody reads until the end fills in minutes and blocks sync
        # in its next write (the first hour-long run stalled so, 20 minutes in)
        sync_log = v.logs / "sync.log"
        sync = subprocess.Popen([sys.executable, "-m", "thermcap", "sync", "--root", str(root), "--to", str(depot),
                                 "--watch", "--interval", "1"], stdout=open(sync_log, "wb"),  # noqa: SIM115
                                stderr=subprocess.STDOUT)
        v.start_recorder("first")
        start = time.monotonic()
        next_mark, next_kill, killed_recorder = start + 3.0, start + CAMERA_KILL_EVERY_S, False
        camera_kills = 0
        while time.monotonic() - start < SOAK_S:
            now = time.monotonic()
            assert sync.poll() is None, f"sync exited: {sync_log.read_bytes()[-3000:].decode(errors='replace')}"
            assert v.recorder is not None and v.recorder.poll() is None
            rss.append(_rss_kib(v.recorder.pid))
            sync_rss.append(_rss_kib(sync.pid))
            if now >= next_mark:
                v.mark(f"mark {len(v.marks)}")
                next_mark = now + MARK_EVERY_S
            if now >= next_kill:  # the camera goes away mid-stream, and comes back
                v.kill_camera()
                assert wait_for(lambda: v.status().get("source_health", {}).get("waiting_for_frames"), 120), \
                    v.tail("recorder")
                v.start_camera()
                written = v.status().get("frames_written", 0)
                assert wait_for(lambda w=written: v.status().get("frames_written", 0) > w + 10, 180), (
                    f"no frame {time.monotonic() - start:.0f} s in, after camera kill {camera_kills + 1}: "
                    f"status {v.status()}\nrecorder: {v.tail('recorder')}\ncamera: {v.tail('camera')}")
                camera_kills += 1
                next_kill = time.monotonic() + CAMERA_KILL_EVERY_S
            if not killed_recorder and now - start >= SOAK_S / 2:  # the recorder dies and is started again
                v.recorder.send_signal(signal.SIGKILL)
                v.recorder.wait(timeout=30)
                killed_recorder = True
                # A real camera lets go of a controller that stopped its heartbeat (after about 3 s);
                # Aravis's fake never does, so it is power-cycled with the recorder, as on a reboot.
                v.kill_camera()
                v.start_camera()
                v.start_recorder("second")  # recovers the first session's open segment as it starts
                rss.clear()  # a new process: its memory is measured from its own start
            time.sleep(0.5)
        assert v.recorder is not None
        v.recorder.send_signal(signal.SIGINT)
        v.recorder.communicate(timeout=300)
        # 4: the camera's gaps, said in the exit status; 3: frames dropped on a loaded machine, counted
        assert v.recorder.returncode in (0, 3, 4), v.tail("recorder")
        # sync ships what is left, then is asked to stop
        def shipped() -> bool:
            left = subprocess.run([sys.executable, "-m", "thermcap", "sync", "--root", str(root), "--to", str(depot),
                                   "--status", "--json"], capture_output=True, text=True, timeout=120)
            st = json.loads(left.stdout) if left.returncode == 0 else {}
            return bool(st) and not st.get("pending") and not st.get("in_flight")
        assert wait_for(shipped, 600, step=1.0), f"sync did not catch up: {sync_log.read_bytes()[-3000:]!r}"
        assert sync.poll() is None, "sync --watch exited on its own"
        sync.send_signal(signal.SIGINT)
        sync.wait(timeout=120)
        # Ctrl-C ends --watch after its pass, cleanly
        assert sync.returncode == 0, sync_log.read_bytes()[-3000:].decode(errors="replace")

    confirm = subprocess.run([sys.executable, "-m", "thermcap", "sync-confirm", "--from", str(depot), "--json"],
                             capture_output=True, text=True, timeout=600)
    assert confirm.returncode == 0, confirm.stderr
    evictions = read_eviction_log(root)
    figures = {}
    checked_marks: list[str] = []
    for session in ("first", "second"):
        frames = _frames_in_depot(depot, session)  # every frame in the depot is the camera's, bit for bit
        meta = json.loads((root / "sessions" / session / "session.json").read_text())
        evicted = [e for e in evictions if e.get("session") == session and "segment" in e]
        shipped_segments = {f.segment for f in frames}
        # evicted before sync shipped them: named in eviction.log with their frame counts
        lost = sum(e.get("frames") or 0 for e in evicted if e["segment"] not in shipped_segments)
        written = meta.get("frames_written")
        assert written == len(frames) + lost, (session, written, len(frames), lost)
        figures[session] = {"in_depot": len(frames), "evicted_before_sync": lost, "written": written,
                            "source_health": meta.get("source_health"), "dropped": meta.get("frames_dropped")}
        # a killed recorder wrote no events.json: its marks' windows are in protected.json, synced as they change
        events_file = depot / "sessions" / session / "events.json"
        events = json.loads(events_file.read_text())["events"] if events_file.is_file() else []
        protected = json.loads((depot / "sessions" / session / "protected.json").read_text())
        windows = {w.get("note"): w for w in protected.get("windows", []) + protected.get("expired", [])}
        for ev in events:
            if ev["kind"] == "source_gap":
                assert ev["frames_missed"] >= 0 and ev["duration_s"] > 0
        by_time = sorted((f.log_time, f.device_frame_id) for f in frames)
        times = np.array([t for t, _ in by_time])
        ids = [i for _, i in by_time]
        health = meta.get("source_health") or {}
        lost = (meta.get("frames_dropped") or 0) + health.get("frames_missed", 0) + health.get("incomplete_frames", 0)
        for mark in (m for m in v.marks if m["session"] == session):
            kept = (mark["answer"].get("keeps") or {}).get("kept", "")
            w = windows.get(mark["note"])
            if w is None or not kept.startswith("whole"):
                continue
            lo, hi = w["start_ns"], w["end_ns"]
            gaps = [g for g in events if g["kind"] == "source_gap" and g["start_ns"] < hi and g["end_ns"] > lo]
            if gaps or (times.size and hi > times[-1]):  # a camera gap, or the recording's end, inside it
                continue
            held = np.flatnonzero((times >= lo) & (times <= hi))
            assert held.size, (mark, w)
            # every frame the camera numbered inside the window is there (the fake's own pace may
            # stall on a loaded machine: time holes are its, id holes would be ours), unless the
            # session counted a loss (dropped, missed, incomplete), which it then says
            window_ids = [ids[k] for k in held]
            steps = [(b - a) % 65535 for a, b in itertools.pairwise(window_ids)]
            assert lost or all(step == 1 for step in steps), (mark, window_ids)
            checked_marks.append(mark["note"])
    assert checked_marks, v.marks  # at least one mark's window was found whole in the depot
    assert camera_kills >= 1 and any(f["source_health"] and f["source_health"].get("gaps") for f in figures.values())
    if len(rss) > 20:  # memory flat: the last third's peak within 64 MiB of the first third's
        third = len(rss) // 3
        assert max(rss[-third:]) < max(rss[:third]) + 64 * 1024, rss
    if len(sync_rss) > 20:
        third = len(sync_rss) // 3
        assert max(sync_rss[-third:]) < max(sync_rss[:third]) + 64 * 1024, sync_rss
    out_dir = os.environ.get("THERMCAP_RELIABILITY_OUT")
    if out_dir:
        Path(out_dir, "vehicle_soak.json").write_text(json.dumps({"soak_s": SOAK_S, "compression": COMPRESSION,
                                                                  "camera_kills": camera_kills, "figures": figures,
                                                                  "marks_checked": checked_marks,
                                                                  "marks": v.marks, "rss_kib": rss,
                                                                  "sync_rss_kib": sync_rss}, indent=2))

