"""``thermcap ls`` lists a root's sessions; reading commands refuse a root that does not exist."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_cli

pytestmark = pytest.mark.integration


def test_ls_lists_sessions_with_their_state_and_copies(tmp_path):
    root = tmp_path / "root"
    assert run_cli("record", "--root", str(root), "--session", "one", "--duration", "0.3", "--width", "64",
                   "--height", "48").returncode == 0
    assert run_cli("archive", "one", "--root", str(root), "--formats", "png16").returncode == 0
    r = run_cli("ls", "--root", str(root), "--json")
    assert r.returncode == 0, r.stderr
    (row,) = json.loads(r.stdout)["sessions"]
    assert row["id"] == "one" and row["state"] == "complete" and row["frames"] > 0
    assert row["archived"] == {"png16": "verified"} and row["bytes"] > 0 and row["duration_s"] > 0
    text = run_cli("ls", "--root", str(root)).stdout
    assert "one" in text and "png16" in text


@pytest.mark.parametrize("command", [["ls"], ["serve", "--port", "0"]])
def test_a_missing_root_is_refused(tmp_path, command):
    missing = tmp_path / "typo"
    r = run_cli(*command, "--root", str(missing))
    assert r.returncode == 1 and str(missing) in r.stderr and "Traceback" not in r.stderr
    assert not missing.exists()


def test_h_is_help_everywhere():
    for command in (["-h"], ["serve", "-h"], ["record", "-h"], ["ctl", "-h"], ["bench", "archive", "-h"],
                    ["report", "-h"]):
        r = run_cli(*command)
        assert r.returncode == 0 and "Usage:" in r.stdout, (command, r.stderr)
