"""Two session folders with one ``session_id`` (a ``cp -a`` backup beside the original): before,
no warning, the index kept one, and opening one folder could return the other's frames. Now the
copy is named in the index's report and not served, and each folder opened reads its own."""

from __future__ import annotations

import json
import shutil

import numpy as np

import thermcap
from thermcap.api.db import make_engine, migrate
from thermcap.api.indexing import index_root
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy


def test_a_copy_with_the_same_id_is_named_and_not_served(tmp_path):
    root = tmp_path / "root"
    Recorder(SimSource(width=32, height=24, frames=20, paced=False, seed=1), root, session_id="patrol",
             policy=SegmentPolicy(max_duration_s=0.5), analysis=False).run()
    # "a-backup" sorts first: the folder named as the id is the session whatever the order
    shutil.copytree(root / "sessions" / "patrol", root / "sessions" / "a-backup")
    seg = next((root / "sessions" / "a-backup").glob("0000.mcap"))
    seg.unlink()  # the copy has diverged: it must not stand in for the original
    engine = make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    migrate(engine)
    report = index_root(engine, root)
    assert "patrol" in report.indexed and "a-backup" not in report.indexed
    assert "patrol" in report.skipped["a-backup"] and "session_id" in report.skipped["a-backup"]
    want = [f.pixels for f in iter_session_frames(root / "sessions" / "patrol")]
    got = thermcap.open(root / "sessions" / "patrol")
    assert len(got) == len(want) and np.array_equal(got.counts(3), want[3])
    copy = thermcap.open(root / "sessions" / "a-backup")  # the copy, opened by its folder, reads itself
    assert len(copy) < len(want)
    assert json.loads((root / "sessions" / "a-backup" / "session.json").read_text())["session_id"] == "patrol"
