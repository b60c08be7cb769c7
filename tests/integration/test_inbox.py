"""``thermcap watch``: files dropped in an inbox are each taken exactly once (by content), with
the TERRA-REF extractor's derived products beside them; a file still being copied waits; a
corrupt one is quarantined with its reason and the queue goes on; a second pass does nothing."""

from __future__ import annotations

import json
import os
import shutil
import time

from tests.conftest import SAMPLES, run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.storage.reader import list_sessions


def test_each_dropped_file_is_taken_once(tmp_path):
    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=6, paced=False, seed=4), tmp_path / "src",
                   session_id="src", analysis=False)
    assert rec.run().ok
    icd = tmp_path / "icd"
    export_session(rec.session_dir, "icd", icd)  # ICD TIFF + JSON pairs, six distinct frames
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    for p in sorted(icd.iterdir()):
        shutil.copy(p, inbox / p.name)
    shutil.copy(next(icd.glob("*.tiff")), inbox / "again_same_bytes.tiff")  # the same content under another name
    (inbox / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe1" + os.urandom(300))  # a corrupt JPEG
    sample = SAMPLES / "flir" / "FLIR_E40.jpg"
    copying = inbox / "still_copying.jpg"
    copying.write_bytes(sample.read_bytes()[:5000] if sample.is_file() else b"x" * 5000)
    # settled two hours ago; the one being copied was written just now. The settle window is an
    # hour, so a loaded machine that takes seconds to start the CLI cannot make it look settled
    old = time.time() - 7200
    for p in inbox.iterdir():
        if p != copying:
            os.utime(p, (old, old))
    root = tmp_path / "root"
    r = run_cli("watch", str(inbox), "--root", str(root), "--once", "--settle", "3600", "--json", "--no-archive")
    assert r.returncode == 1, r.stderr  # one file quarantined
    res = json.loads(r.stdout)
    assert len(res["processed"]) == 6
    assert len(res["duplicates"]) == 1  # whichever name came second, the content is taken once
    assert res["waiting"] == ["still_copying.jpg"]
    assert set(res["quarantined"]) == {"broken.jpg"} and "broken.jpg" in res["quarantined"]["broken.jpg"]
    assert (inbox / "quarantine" / "broken.jpg").is_file()
    assert (inbox / "quarantine" / "broken.jpg.reason.txt").read_text().strip()
    assert len(list_sessions(root)) == 6
    one = res["processed"][0]
    derived = inbox / (one["path"] + ".derived")
    assert list(derived.glob("*.png")) and list(derived.glob("*.celsius.tiff")) and (derived / "summary.json").is_file()
    again = json.loads(run_cli("watch", str(inbox), "--root", str(root), "--once", "--settle", "3600", "--json",
                               "--no-archive").stdout)
    assert again["processed"] == [] and again["quarantined"] == {}  # nothing twice
    assert len(list_sessions(root)) == 6


def test_a_crash_between_import_and_journal_imports_nothing_twice(tmp_path):
    import hashlib

    from thermcap.api.jobs.inbox import process_inbox

    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=2, paced=False, seed=8), tmp_path / "src",
                   session_id="src", analysis=False)
    assert rec.run().ok
    icd = tmp_path / "icd"
    export_session(rec.session_dir, "icd", icd)
    inbox, root = tmp_path / "inbox", tmp_path / "root"
    inbox.mkdir()
    a, b = sorted(icd.glob("*.tiff"))
    for p in (a, b):
        shutil.copy(p, inbox / p.name)
        shutil.copy(p.with_suffix(".json"), inbox / p.with_suffix(".json").name)
    first = process_inbox(inbox, root, settle_s=0)
    assert len(first.processed) == 2
    sessions = sorted(p.name for p in list_sessions(root))
    # the journal lost both entries (a crash after importing, before journaling); one session half-made
    (inbox / ".thermcap" / "inbox.jsonl").unlink()
    half = root / "sessions" / f"inbox-{hashlib.sha256((inbox / b.name).read_bytes()).hexdigest()[:16]}"
    meta = json.loads((half / "session.json").read_text())
    (half / "session.json").write_text(json.dumps({**meta, "status": "recording"}))
    again = process_inbox(inbox, root, settle_s=0)
    assert len(again.processed) == 2
    assert sorted(p.name for p in list_sessions(root)) == sessions  # the same two sessions, none twice
    assert json.loads((half / "session.json").read_text())["status"] == "complete"  # re-imported whole


def test_files_taken_as_dask_tasks_are_journaled_once(tmp_path):
    """The same inbox pass with its files taken in parallel as tasks on a Dask cluster."""
    from distributed import Client, LocalCluster

    from thermcap.api.jobs.inbox import process_inbox

    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=5, paced=False, seed=6), tmp_path / "src",
                   session_id="src", analysis=False)
    assert rec.run().ok
    inbox, root = tmp_path / "inbox", tmp_path / "root"
    export_session(rec.session_dir, "icd", inbox)
    (inbox / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe1" + os.urandom(300))
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        res = process_inbox(inbox, root, settle_s=0, archive_formats=["png16"], client=client)
        again = process_inbox(inbox, root, settle_s=0, archive_formats=["png16"], client=client)
    assert len(res.processed) == 5 and set(res.quarantined) == {"broken.jpg"}
    assert all(r["archived"] for r in res.processed)
    assert again.processed == [] and again.quarantined == {}
    assert len(list_sessions(root)) == 5
    journal = (inbox / ".thermcap" / "inbox.jsonl").read_text().splitlines()
    assert len(journal) == 6
