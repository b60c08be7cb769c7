"""Issue 36: every CLI value is validated at parse time, in the option's own terms. These were
tracebacks (``--fps inf``, ``--width 100000``, ``--control-port 99999``), were taken without a
word (``--duration -1``, ``--min-free 150%``, ``--ring --max-disk 1K``, ``serve --port 99999``),
failed after seven frames (``--level 99``), or wrote outside the data root (``--session ../../x``)."""

from __future__ import annotations

import pytest

from tests.conftest import run_cli

BAD_RECORD = [
    (["--fps", "inf"], "--fps"),
    (["--fps", "nan"], "--fps"),
    (["--fps", "0"], "--fps"),
    (["--width", "100000", "--height", "100000"], "--width"),
    (["--width", "8193", "--height", "8193"], "--width"),
    (["--duration", "-1"], "--duration"),
    (["--segment-duration", "-1"], "--segment-duration"),
    (["--pre", "-5"], "--pre"),
    (["--queue", "-1"], "--queue"),
    (["--queue", "0"], "--queue"),
    (["--ring", "--min-free", "150%"], "--min-free"),
    (["--ring", "--max-disk", "1K"], "--max-disk"),
    (["--ring", "--max-disk", "nanG"], "nanG"),
    (["--level", "99"], "--level"),
    (["--compression", "lz4", "--level", "20"], "--level"),
    (["--session", "../../x"], "session id"),
    (["--session", ".hidden"], "session id"),
    (["--control-port", "99999"], "--control-port"),
    (["--live", "--live-host", "0.0.0.0"], "--live-host"),
    (["--control"], "token"),
]


@pytest.mark.parametrize(("args", "named"), BAD_RECORD, ids=[" ".join(a) for a, _ in BAD_RECORD])
def test_record_refuses_an_absurd_value_before_recording(tmp_path, args, named):
    r = run_cli("record", "--root", str(tmp_path), "--duration", "0.2", *args,
                env={"THERMCAP_CONTROL_TOKEN": ""})
    assert r.returncode != 0, r.stdout
    assert named in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "sessions").exists() or not any((tmp_path / "sessions").iterdir())
    assert not (tmp_path.parent / "x").exists()


@pytest.mark.parametrize("port", ["99999", "-1", "http"])
def test_serve_refuses_a_port_that_cannot_be(tmp_path, port):
    r = run_cli("serve", "--root", str(tmp_path), "--port", port)
    assert r.returncode == 2 and "--port" in r.stderr and "Traceback" not in r.stderr


def test_record_exits_nonzero_when_frames_were_dropped(tmp_path):
    """A writer slower than the paced source: frames are dropped, and the exit says so."""
    r = run_cli("record", "--root", str(tmp_path), "--duration", "1", "--width", "64", "--height", "48",
                "--queue", "1", "--no-analysis", "--debug-writer-delay", "0.05", "--json")
    assert r.returncode == 3, (r.returncode, r.stderr)
    assert "frames were dropped" in r.stderr


def test_control_insecure_is_an_explicit_choice(tmp_path):
    r = run_cli("record", "--root", str(tmp_path), "--duration", "0.3", "--width", "64", "--height", "48",
                "--control", "--control-insecure", "--no-analysis", env={"THERMCAP_CONTROL_TOKEN": ""})
    assert r.returncode == 0, r.stderr


OTHER = [
    (["archive", "x", "--workers", "0"], "--workers"),
    (["analyze", "x", "--threshold", "nan"], "--threshold"),
    (["sync", "--part-size", "1"], "--part-size"),
    (["audit", "--project-days", "0"], "--project-days"),
    (["report", "quality", "x", "--blackbody", "inf"], "--blackbody"),
    (["gc", "--keep-days", "-1"], "--keep-days"),  # issue 65, defect 17: it was accepted
    (["gc", "--keep-days", "nan"], "--keep-days"),
]


@pytest.mark.parametrize(("args", "named"), OTHER, ids=[" ".join(a) for a, _ in OTHER])
def test_other_commands_refuse_absurd_values_at_parse_time(tmp_path, args, named):
    r = run_cli(*args, "--root", str(tmp_path))
    assert r.returncode == 2 and named in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_play_serves_its_tokenless_view_on_this_machine_only(tmp_path):
    """Issue 65 (17): ``play --host 0.0.0.0`` served a session to the network with no token; the
    rule ``record --live`` keeps is now one check both use."""
    r = run_cli("play", "any-session", "--root", str(tmp_path), "--host", "0.0.0.0", "--duration", "1")
    assert r.returncode == 1 and "--host 0.0.0.0" in r.stderr and "SSH tunnel" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("command", [["archive"], ["verify"], ["cut", "--out", "c.mcap"], ["info"]])
def test_a_folder_that_is_not_a_session_is_refused_untouched(tmp_path, command):
    """Issue 65 (13): ``archive --root R /etc`` created /etc/archive/ and /etc/.lock before failing.
    Every command that takes a session checks it holds one before it writes anything there."""
    folder = tmp_path / "not-a-session"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    r = run_cli(command[0], str(folder), "--root", str(tmp_path / "root"), *command[1:], cwd=tmp_path)
    assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
