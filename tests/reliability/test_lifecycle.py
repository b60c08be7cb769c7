"""A session's whole life against a live API, with the faults of the integrity issue injected:
record -> kill -9 (with a `recover` racing the live recorder) -> recover -> archive (every subset
of formats) -> damage a copy -> delete-source or gc -> scrub -> scrub --repair.

After every step: every frame's counts, sidecar and time are served bit-exact over real HTTP by
at least one path, and `info`, the catalog and session.json agree on the frame count.

THERMCAP_LIFECYCLE=full runs every one of the 15 subsets of png16, tiff-lzw, hdf5 and jxl; the
default (CI) run takes 6 of them, each format alone, one pair and all four. The figures for
tests/reliability/README.md come from the JSON report it writes (THERMCAP_RELIABILITY_OUT).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import httpx
import numpy as np
import pytest
from mcap.reader import make_reader

from tests.conftest import ApiServer, run_cli, wait_for
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import decode_image

pytestmark = pytest.mark.slow  # a reliability run: CI runs its short form, `-m "not slow"` skips it

W, H, FPS = 96, 64, 60
FORMATS = ("png16", "tiff-lzw", "hdf5", "jxl")
ALL_SUBSETS = [list(c) for n in range(1, 5) for c in itertools.combinations(FORMATS, n)]
SHORT_SUBSETS = [["png16"], ["tiff-lzw"], ["hdf5"], ["jxl"], ["png16", "hdf5"], list(FORMATS)]


def _truth(session: Path) -> list[tuple[int, str, bytes]]:
    """(log time, pixel sha256, sidecar bytes) of every frame the segments hold."""
    out = []
    for seg in sorted(session.glob("[0-9][0-9][0-9][0-9].mcap")):
        pending: dict[int, list] = {}
        with open(seg, "rb") as f:
            for _, ch, msg in make_reader(f).iter_messages(topics=["/thermal/image", "/thermal/metadata"]):
                slot = pending.setdefault(msg.log_time, [None, None])
                if ch.topic == "/thermal/image":
                    px = decode_image(msg.data)[1]
                    slot[0] = hashlib.sha256(np.ascontiguousarray(px, "<u2").tobytes()).hexdigest()
                else:
                    slot[1] = json_payload(ch.message_encoding, msg.data)  # the sidecar as recorded
        out += [(t, v[0], v[1]) for t, v in sorted(pending.items())]
    return out


def _flip_one_bit(path: Path) -> None:
    data = bytearray(path.read_bytes())
    if path.suffix == ".zip":  # inside an image entry, not the directory
        with zipfile.ZipFile(path) as zf:
            info = next(i for i in zf.infolist() if not i.filename.endswith(".json"))
        at = info.header_offset + 30 + len(info.filename) + 8
    else:
        at = len(data) // 2
    data[at] ^= 0x20
    path.write_bytes(bytes(data))


class Checker:
    def __init__(self, server: ApiServer, root: Path) -> None:
        self.client = httpx.Client(base_url=server.url, timeout=60)
        self.root = root
        self.frames_checked = 0
        self.frames_lost = 0

    def reindex(self) -> None:
        r = self.client.post("/api/v1/index", params={"force": "true"})
        assert r.status_code == 200, r.text

    def served(self, sid: str, truth: list[tuple[int, str, bytes]], step: str) -> None:
        self.reindex()
        row = self.client.get(f"/api/v1/sessions/{sid}").json()
        assert row["frames"] == len(truth), (step, row["frames"], len(truth))
        listed = self.client.get(f"/api/v1/sessions/{sid}/frames", params={"limit": 1000}).json()["items"]
        assert [f["timestamp_ns"] for f in listed] == [t for t, _, _ in truth], step
        lost = 0
        for i, (_t, sha, sidecar) in enumerate(truth):
            raw = self.client.get(f"/api/v1/sessions/{sid}/frames/{i}", params={"format": "raw"})
            meta = self.client.get(f"/api/v1/sessions/{sid}/frames/{i}/metadata")
            ok = raw.status_code == 200 and hashlib.sha256(raw.content).hexdigest() == sha \
                and meta.status_code == 200 and meta.json() == json.loads(sidecar)
            lost += not ok
        self.frames_checked += len(truth)
        self.frames_lost += lost
        assert lost == 0, f"{step}: {lost} frames not served bit-exact"
        info = json.loads(run_cli("info", str(self.root / "sessions" / sid), "--json").stdout)
        meta = json.loads((self.root / "sessions" / sid / "session.json").read_text())
        assert info["frames"] == row["frames"] == meta["frames_written"], (step, info["frames"], meta["frames_written"])


def test_the_whole_life_of_a_session_loses_nothing(tmp_path, monkeypatch):
    subsets = ALL_SUBSETS if os.environ.get("THERMCAP_LIFECYCLE") == "full" else SHORT_SUBSETS
    root = tmp_path / "root"
    root.mkdir()
    monkeypatch.delenv("THERMCAP_TOKENS", raising=False)  # served without tokens (set, even empty, means tokens)
    server = ApiServer(root)
    check = Checker(server, root)
    report = []
    try:
        for n, formats in enumerate(subsets):
            sid = f"life{n:02d}"
            session = root / "sessions" / sid
            proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--duration", "30", "--width", str(W),
                                     "--height", str(H), "--segment-duration", "0.5", "--seed", str(n), "--root",
                                     str(root), "--session", sid, "--no-analysis"],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            assert wait_for(lambda s=session: len(list(s.glob("*.mcap"))) >= 2, timeout=30)
            racing = run_cli("recover", str(root))  # defect 1: a recover racing the live recorder
            assert racing.returncode == 0, racing.stderr
            closed = {p.name: p.read_bytes() for p in session.glob("*.mcap")}
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            for name, data in closed.items():
                assert (session / name).read_bytes() == data, "a closed segment changed"
            info = json.loads(run_cli("info", str(session), "--json").stdout)
            assert info["status"] == "interrupted"
            r = run_cli("recover", str(session))
            assert r.returncode == 0, r.stderr
            truth = _truth(session)
            assert len(truth) > 60
            expected = SimSource(width=W, height=H, fps=FPS, seed=n, paced=False, frames=len(truth)).frames()
            for (_, sha, _), exp in zip(truth, expected, strict=True):
                assert sha == hashlib.sha256(np.ascontiguousarray(exp.pixels, "<u2").tobytes()).hexdigest()
            check.served(sid, truth, "recovered")

            r = run_cli("archive", sid, "--root", str(root), "--formats", ",".join(formats))
            assert r.returncode == 0, r.stderr
            check.served(sid, truth, "archived")

            # a bit flips in one archived copy: never served, the next verified copy is
            victim_fmt = formats[0]
            victim = sorted((session / "archive" / victim_fmt).iterdir())[0]
            _flip_one_bit(victim)
            check.served(sid, truth, f"{victim_fmt} damaged")

            if len(formats) > 1 and n % 2 == 0:
                r = run_cli("archive", sid, "--root", str(root), "--formats", ",".join(formats[1:]), "--delete-source")
                assert r.returncode == 0, r.stderr
                check.served(sid, truth, "source deleted")
            elif len(formats) > 1:
                dry = json.loads(run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", "--dry-run").stdout)
                mine = next(d for d in dry["decisions"] if d["session"] == str(session))
                assert mine["action"] == "keep"  # the damaged format is still requested: not covered
                check.served(sid, truth, "gc kept it")
            r = run_cli("scrub", str(root), "--session", sid, "--json")
            assert r.returncode == 1
            found = json.loads(r.stdout)["findings"]
            assert [f["copy"] for f in found] == [victim_fmt]
            check.served(sid, truth, "scrubbed")
            r = run_cli("scrub", str(root), "--session", sid, "--repair", "--json")
            assert r.returncode == 0, r.stdout + r.stderr
            assert run_cli("verify", str(session)).returncode == 0
            check.served(sid, truth, "repaired")
            if len(formats) > 1 and n % 2 == 1:
                r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json")
                assert r.returncode == 0, r.stderr
                assert not list(session.glob("*.mcap"))  # covered now: the source went, the archive stays
                check.served(sid, truth, "gc deleted the source")
            report.append({"formats": formats, "frames": len(truth), "closed_segments": len(closed)})
    finally:
        server.stop()
    out = Path(os.environ.get("THERMCAP_RELIABILITY_OUT", tmp_path)) / "lifecycle.json"
    out.write_text(json.dumps({"sessions": report, "frames_checked": check.frames_checked,
                               "frames_lost": check.frames_lost}, indent=1))
    assert check.frames_lost == 0
