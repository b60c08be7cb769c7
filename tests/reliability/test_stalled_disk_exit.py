"""A disk whose fsync never returns must not hold the recorder's exit.

An NFS mount gone away, a dying SD card or a USB disk pulled under load: ``fsync`` blocks for
ever. The frames were written (they sit complete in ``.active`` files, in the page cache), but
the disk never confirmed them. The recorder must stop within its settle deadline, say which
segments the disk did not confirm and what to run once it answers, and exit non-zero; and once
the disk answers again, ``recover`` must give back every frame.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from mcap.reader import make_reader

from thermcap.recorder.icd.topics import TOPIC_IMAGE

# The disk stalls at the first segment's close and never answers again: every fsync from then
# on (segments, the folder, session.json) blocks for ever.
STALLED_DISK = textwrap.dedent("""
    import os, sys, threading
    real, stalled, forever = os.fsync, threading.Event(), threading.Event()
    def fsync(fd):
        try:
            name = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            name = ""
        if name.endswith(".mcap.active"):
            stalled.set()
        if stalled.is_set():
            print("thermcap-test: fsync stalled", name, file=sys.stderr, flush=True)
            forever.wait()
        real(fd)
    os.fsync = fsync
    from thermcap.cli import main
    sys.argv = ["thermcap", *sys.argv[1:]]
    main()
""")


def _frames(folder) -> int:
    n = 0
    for seg in sorted(folder.glob("*.mcap")):
        with open(seg, "rb") as f:
            n += sum(1 for _ in make_reader(f).iter_messages(topics=[TOPIC_IMAGE]))
    return n


def _confirmed(folder) -> int:
    """Frames in segments with their final name: renamed only after fsync returned."""
    return _frames(folder)


def test_a_disk_that_never_answers_does_not_hold_the_exit(tmp_path):
    root = tmp_path / "data"
    proc = subprocess.run(
        [sys.executable, "-c", STALLED_DISK, "record", "--root", str(root), "--session", "s", "--duration", "1.5",
         "--fps", "20", "--width", "64", "--height", "48", "--segment-duration", "0.5", "--no-analysis",
         "--settle-timeout", "2", "--json"],
        capture_output=True, text=True, timeout=120)
    assert "fsync stalled" in proc.stderr, proc.stderr  # the fault was really injected
    assert proc.returncode != 0, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert "disk has not confirmed" in proc.stderr, proc.stderr
    assert "0000.mcap" in proc.stderr, proc.stderr
    assert "thermcap recover" in proc.stderr, proc.stderr
    # No frame the disk never confirmed is counted as written (a power cut may still take it):
    # they are counted apart, and together they are every frame captured.
    summary = json.loads(proc.stdout)
    assert summary["frames_written"] == _confirmed(root / "sessions" / "s")
    assert summary["frames_unconfirmed"] > 0
    assert summary["frames_written"] + summary["frames_unconfirmed"] == summary["frames_captured"] == 30
    session = root / "sessions" / "s"
    assert sorted(p.name for p in session.glob("*.mcap.active")), "the unconfirmed segments stay for recover"
    # The disk answers again: recover names the finished segments and keeps every frame.
    rec = subprocess.run([sys.executable, "-m", "thermcap", "recover", str(session)],
                         capture_output=True, text=True, timeout=120)
    assert rec.returncode == 0, rec.stdout + rec.stderr
    assert not list(session.glob("*.active"))
    assert _frames(session) == 30
