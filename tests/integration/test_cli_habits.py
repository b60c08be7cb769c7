"""CLI habits as a user meets them in a script or a log: progress lines instead of silence when
stderr is not a terminal, --quiet, each session's result as soon as it is done, ``info`` as a
plain table in a pipe, and one config file for record, serve and worker."""

from __future__ import annotations

import json

from tests.conftest import run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource


def _root(tmp_path, n=2):
    for i in range(n):
        Recorder(SimSource(width=64, height=48, fps=30, frames=30, paced=False, seed=i), tmp_path,
                 session_id=f"s{i}", analysis=False).run()
    return tmp_path


def test_archive_all_reports_progress_and_each_session_in_a_log(tmp_path):
    root = _root(tmp_path)
    r = run_cli("archive", "--all", "--root", str(root), "--formats", "png16")
    assert r.returncode == 0, r.stderr
    assert "... s0 (1/2)" in r.stderr and "... s1 (2/2)" in r.stderr  # not a terminal: lines, not silence
    assert r.stdout.count(": archived") == 2
    quiet = run_cli("-q", "archive", "--all", "--root", str(root), "--formats", "tiff-lzw", "--force")
    assert quiet.returncode == 1  # nothing left for --all (both archived): said, even when quiet
    quiet = run_cli("-q", "archive", "s0", "--root", str(root), "--formats", "tiff-lzw")
    assert quiet.returncode == 0 and "..." not in quiet.stderr


def test_info_in_a_pipe_is_a_plain_table(tmp_path):
    root = _root(tmp_path, 1)
    r = run_cli("info", str(root / "sessions" / "s0"))
    assert r.returncode == 0, r.stderr
    assert not any(ch in r.stdout for ch in "┏┃━│└"), r.stdout
    line = next(x for x in r.stdout.splitlines() if x.startswith("frames:"))
    assert "effective fps" in line  # not wrapped at 80 columns
    assert any(x.split()[:2] == ["/thermal/image", "30"] for x in r.stdout.splitlines())


def test_one_config_file_for_serve(tmp_path):
    root = _root(tmp_path, 1)
    cfg = tmp_path / "thermcap.toml"
    cfg.write_text(f'[serve]\nroot = "{root}"\n\n[worker]\nformats = "png16"\n')
    r = run_cli("--config", str(cfg), "serve", "--get", "/api/v1/sessions")
    assert r.returncode == 0, r.stderr
    assert [s["id"] for s in json.loads(r.stdout)["items"]] == ["s0"]
    assert run_cli("--config", str(cfg), "worker", "--help").returncode == 0
