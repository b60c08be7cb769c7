"""The inbox under load: files dropped (slowly, as a copy over a network share writes them) while
two `thermcap watch` processes run on the same inbox, one of them killed with SIGKILL part-way.

- Every good file is taken exactly once: one journal entry and one session per content.
- Every session is the file's frame, bit-exact. A half-copied file taken early would import
  a truncated image, or be quarantined as corrupt.
- Every corrupt file is quarantined with its reason, and the queue goes on.

The default run drops 40 files; THERMCAP_INBOX=full drops 200 (figures in
tests/reliability/README.md).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import tifffile

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.storage.digest import frame_sha256
from thermcap.recorder.storage.reader import iter_session_frames, list_sessions

FULL = os.environ.get("THERMCAP_INBOX") == "full"
N_FILES = 200 if FULL else 40
N_CORRUPT = N_FILES // 20
SETTLE_S = 1.5
PAUSE_S = 0.4  # between the halves of a file: well inside the settle time, as a slow copy is


def _watch(inbox, root):
    return subprocess.Popen([sys.executable, "-m", "thermcap", "watch", str(inbox), "--root", str(root),
                             "--interval", "0.3", "--settle", str(SETTLE_S), "--formats", "png16", "--json"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _journal(inbox):
    path = inbox / ".thermcap" / "inbox.jsonl"
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()] if path.is_file() else []


def test_files_dropped_while_two_watchers_run_are_each_taken_once(tmp_path):
    good = N_FILES - N_CORRUPT
    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=good, paced=False, seed=12), tmp_path / "src",
                   session_id="src", analysis=False)
    assert rec.run().ok
    icd = tmp_path / "icd"
    export_session(rec.session_dir, "icd", icd)
    tiffs = sorted(icd.glob("*.tiff"))
    assert len(tiffs) == good
    want = {p.name: frame_sha256(tifffile.imread(p)) for p in tiffs}
    corrupt = {}
    for k in range(N_CORRUPT):  # a TIFF cut short, or bytes that are no image at all
        data = tiffs[k].read_bytes()[:300] if k % 2 else b"\xff\xd8\xff\xe1" + os.urandom(400)
        corrupt[f"broken_{k:03d}" + (".tiff" if k % 2 else ".jpg")] = data
    inbox, root = tmp_path / "inbox", tmp_path / "root"
    inbox.mkdir()
    watchers = [_watch(inbox, root), _watch(inbox, root)]

    def drop():
        items = [(p.name, p.read_bytes(), p.with_suffix(".json")) for p in tiffs]
        items += [(name, data, None) for name, data in corrupt.items()]
        rng = np.random.default_rng(3)
        for i in rng.permutation(len(items)):
            name, data, sidecar = items[i]
            if sidecar is not None:
                shutil.copy(sidecar, inbox / sidecar.name)  # the ICD sidecar first, then its image
            with open(inbox / name, "wb") as f:  # in two halves, as a slow copy writes it
                f.write(data[: len(data) // 2])
                f.flush()
                time.sleep(PAUSE_S if i % 4 == 0 else 0.0)
                f.write(data[len(data) // 2:])

    dropper = threading.Thread(target=drop)
    t0 = time.monotonic()
    dropper.start()
    killed = False
    try:
        deadline = time.monotonic() + (1200 if FULL else 400)
        while time.monotonic() < deadline:
            done = _journal(inbox)
            if not killed and len(done) >= N_FILES // 3:
                watchers[0].send_signal(signal.SIGKILL)  # mid-stream: the other takes the whole queue
                killed = True
            if not dropper.is_alive() and len(done) >= N_FILES:
                break
            time.sleep(0.3)
        dropper.join()
        elapsed = time.monotonic() - t0
    finally:
        for w in watchers:
            w.kill()
            w.wait()
    assert killed
    journal = _journal(inbox)
    by_path = {}
    for rec_ in journal:
        assert rec_["path"] not in by_path, f"{rec_['path']} was taken twice"
        by_path[rec_["path"]] = rec_
    assert len({r["sha256"] for r in journal}) == len(journal) == N_FILES, (len(journal), N_FILES)
    assert {p for p, r in by_path.items() if r["status"] == "quarantined"} == set(corrupt)
    for name in corrupt:
        assert (inbox / "quarantine" / name).is_file() and (inbox / "quarantine" / f"{name}.reason.txt").read_text()
    sessions = list_sessions(root)
    assert len(sessions) == good  # one session per good file, none twice
    for name, digest in want.items():
        rec_ = by_path[name]
        assert rec_["status"] == "processed" and rec_["archived"], rec_
        frames = list(iter_session_frames(rec_["sessions"][0]))
        assert len(frames) == 1 and frame_sha256(frames[0].pixels) == digest, name  # the whole file, bit-exact
    out = os.environ.get("THERMCAP_RELIABILITY_OUT")
    if out:
        with open(os.path.join(out, "inbox_drop.json"), "w") as f:
            json.dump({"files": N_FILES, "corrupt": N_CORRUPT, "seconds": round(elapsed, 1),
                       "files_per_s": round(N_FILES / elapsed, 2), "taken_twice": 0,
                       "quarantined": len(corrupt), "sessions": len(sessions)}, f)
