"""The shipped vehicle configuration (docs/deploy/recorder.toml, run by the systemd unit) works
as it is: every key is an option of ``thermcap record``, and recording with it (cameras fed from
files instead of the FIFOs, a temp root and free ports) gives each camera's frames bit-exact."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from tests.conftest import run_cli
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

DEPLOY = Path(__file__).resolve().parents[3] / "docs" / "deploy"


def test_the_unit_runs_thermcap_record_with_the_config_from_its_environment():
    unit = (DEPLOY / "thermcap-recorder.service").read_text()
    (cmd,) = re.findall(r"^ExecStart=/usr/bin/env thermcap (.*)$", unit, re.M)
    env = dict(line.split("=", 1) for line in (DEPLOY / "recorder.env.example").read_text().splitlines()
               if line and not line.startswith("#"))
    assert env["THERMCAP_CONFIG"] == "/etc/thermcap/recorder.toml"
    assert "EnvironmentFile=/etc/thermcap/recorder.env" in unit
    r = run_cli("--config", str(DEPLOY / "recorder.toml"), *cmd.split(), "--help")
    assert r.returncode == 0, r.stderr


def test_recording_with_the_shipped_config(tmp_path):
    text = (DEPLOY / "recorder.toml").read_text()
    rng = np.random.default_rng(7)
    frames = {}
    for name, (w, h, n) in {"front": (640, 512, 12), "rear": (640, 512, 12), "mast": (320, 256, 6)}.items():
        px = rng.integers(0, 1 << 14, size=(n, h, w), dtype=np.uint16)
        path = tmp_path / f"{name}.raw"
        px.astype("<u2").tofile(path)
        frames[name] = px
        text = text.replace(f"/run/thermcap/{name}.fifo", str(path))
    text = text.replace('"/var/lib/thermcap"', f'"{tmp_path / "data"}"')
    cfg = tmp_path / "recorder.toml"
    cfg.write_text(text)
    r = run_cli("--config", str(cfg), "record", "--session", "v", "--control-port", "0", "--live-port", "0",
                "--max-disk", "1G", "--min-free", "1", "--json", env={"THERMCAP_CONTROL_TOKEN": "t" * 32})
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert {n: c["frames_written"] for n, c in res["cameras"].items()} == {"front": 12, "rear": 12, "mast": 6}
    session = tmp_path / "data" / "sessions" / "v"
    meta = read_session_meta(session)
    assert meta["ring"]["pre_s"] == 30 and set(meta["cameras"]) == {"front", "rear", "mast"}
    for name, px in frames.items():
        got = [f.pixels for f in iter_session_frames(session, name)]
        assert len(got) == len(px) and all(np.array_equal(a, b) for a, b in zip(got, px, strict=True)), name
