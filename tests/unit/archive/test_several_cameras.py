"""A session of several cameras is not archived yet: the archiver says so and changes nothing
(reading it as a one-camera session would have archived zero frames as a verified copy)."""

from __future__ import annotations

import pytest

from thermcap.archive.archiver import archive_session
from thermcap.archive.exceptions import ArchiveError
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource


def test_the_archiver_refuses_a_session_of_several_cameras_and_keeps_it(tmp_path):
    cams = {n: SimSource(width=40, height=32, fps=30, frames=5, paced=False, seed=i) for i, n in enumerate("ab")}
    rec = Recorder(cams, tmp_path, session_id="ab", analysis=False)
    assert rec.run().ok
    before = {p.name: p.read_bytes() for p in rec.session_dir.iterdir() if p.is_file()}
    with pytest.raises(ArchiveError, match="several cameras"):
        archive_session(rec.session_dir, ["png16"], delete_source=True)
    after = {p.name: p.read_bytes() for p in rec.session_dir.iterdir() if p.is_file()}
    assert after == before and not (rec.session_dir / "archive").exists()
