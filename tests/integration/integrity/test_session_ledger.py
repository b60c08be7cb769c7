"""Issue 65, defects 6 and 7: what a session says it wrote is its ledger.

7: `rm 0001.mcap` from a complete 3-segment session: `info` said "complete ... frames: 120" with
no warning while session.json said 180 were written, and `archive --delete-source` would have
closed the case on 120. 6: a segment the archive never saw, put back beside an archived
session, was deleted by `archive --delete-source` ("archived (MCAP source deleted)")."""

from __future__ import annotations

import json
import shutil

import pytest

from tests.conftest import run_cli

pytestmark = pytest.mark.integration


@pytest.fixture
def three(tmp_path):
    root = tmp_path / "root"
    r = run_cli("record", "--root", str(root), "--session", "s", "--duration", "1.5", "--segment-duration", "0.5",
                "--width", "64", "--height", "48", "--no-analysis")
    assert r.returncode == 0, r.stderr
    session = root / "sessions" / "s"
    assert len(sorted(session.glob("*.mcap"))) >= 3
    return root, session


def test_a_segment_gone_without_a_record_is_said_and_keeps_the_rest(three):
    root, session = three
    written = json.loads((session / "session.json").read_text())["frames_written"]
    gone = sorted(session.glob("*.mcap"))[1]
    frames_in_it = next(s["frames"] for s in json.loads((session / "session.json").read_text())["segments"]
                        if s["name"] == gone.name)
    gone.unlink()
    info = json.loads(run_cli("info", str(session), "--json").stdout)
    assert info["lost_segments"] == [{"name": gone.name, "frames": frames_in_it}], info["lost_segments"]
    assert info["frames_lost"] == frames_in_it and info["frames"] == written - frames_in_it
    assert "missing" in (info["hint"] or "")
    said = run_cli("info", str(session))
    assert gone.name in said.stdout + said.stderr
    left = sorted(p.name for p in session.glob("*.mcap"))
    r = run_cli("archive", "s", "--root", str(root), "--formats", "png16", "--delete-source")
    assert r.returncode != 0 and gone.name in r.stderr, (r.stdout, r.stderr)
    assert sorted(p.name for p in session.glob("*.mcap")) == left  # nothing deleted on that archive


def test_a_segment_the_archive_never_saw_is_never_deleted_with_it(three):
    root, session = three
    assert run_cli("archive", "s", "--root", str(root), "--formats", "png16").returncode == 0
    # a segment restored beside it (a copy back from a depot of another run: other frames)
    stranger = session / "0009.mcap"
    shutil.copy(sorted(session.glob("*.mcap"))[0], stranger)
    r = run_cli("archive", "s", "--root", str(root), "--formats", "png16", "--delete-source")
    assert r.returncode != 0 and "0009.mcap" in r.stderr, (r.stdout, r.stderr)
    assert stranger.exists() and len(list(session.glob("*.mcap"))) >= 4
