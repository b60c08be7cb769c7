"""An event window (a mark, a trigger) is kept by everything that deletes: the ring's evictor,
``thermcap gc`` and ``thermcap archive --delete-source`` alike, unless the user says otherwise."""

from __future__ import annotations

import json
import shutil

from thermcap.api.jobs.retention import gc_sessions
from thermcap.archive.archiver import archive_session
from thermcap.recorder.storage.ring import ProtectionBook, Window


def _protect(session_dir) -> None:
    first = min(p for p in session_dir.glob("*.mcap"))
    from thermcap.recorder.storage.reader import segment_span

    start, end, _ = segment_span(first)
    ProtectionBook(session_dir).add(Window(start, end, "mark", "deer on the road"))


def test_archive_delete_source_keeps_a_protected_session(session):
    _protect(session)
    segments = sorted(p.name for p in session.glob("*.mcap"))
    m = archive_session(session, ["png16"], delete_source=True)
    assert sorted(p.name for p in session.glob("*.mcap")) == segments
    assert not m["source"].get("deleted")
    assert "protected" in m["source"].get("kept_because", "")


def test_gc_keeps_a_protected_session_unless_told(session, tmp_path):
    root = tmp_path / "root"
    (root / "sessions").mkdir(parents=True)
    d = root / "sessions" / "s"
    shutil.move(session, d)
    archive_session(d, ["png16", "tiff-lzw", "hdf5"])
    _protect(d)
    res = gc_sessions(root, keep_days=0, max_bytes=None, require_upload=False, dry_run=False)
    (decision,) = res.decisions
    assert decision.action == "keep" and "protected" in (decision.why_kept or ""), decision
    assert list(d.glob("*.mcap"))
    res = gc_sessions(root, keep_days=0, max_bytes=None, require_upload=False, dry_run=False,
                      include_protected=True)
    assert res.decisions[0].action == "delete-source"
    assert not list(d.glob("*.mcap"))
    assert json.loads((d / "protected.json").read_text())["windows"]  # the record of the event stays
