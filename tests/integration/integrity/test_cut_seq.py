"""Defect 14: a real FLIR CSQ/SEQ whose last record ends a few bytes short was refused whole.

Issue 36 sharpened it: an image whose image stream is complete is a complete frame even when its
directory promises a few bytes more (the short trailer is noted); only an image whose pixels (or
the calibration its temperatures need) are cut is truncated."""

from __future__ import annotations

import hashlib
import json

import numpy as np
from mcap.reader import make_reader

from tests.conftest import run_cli
from thermcap.recorder.icd.topics import decode_image


def test_a_seq_whose_last_trailer_is_short_keeps_every_image(samples, tmp_path):
    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "short.seq"
    seq.write_bytes((fff * 3)[:-4])  # three images back to back, the last one's GPS record 4 bytes short
    r = run_cli("import", str(seq), "--root", str(tmp_path / "root"), "--session", "short", "--json",
                "--no-analysis")
    assert r.returncode == 0, r.stderr
    report = json.loads(r.stdout)
    assert report["failed"] == [] and report["truncated"] == []
    assert len(report["files"]) == 3
    session = tmp_path / "root" / "sessions" / "short"
    assert len(_frames(session)) == 3


def _frames(session):
    frames = []
    for seg in sorted(session.glob("*.mcap")):
        with open(seg, "rb") as f:
            frames += [decode_image(m.data)[1].copy() for _, _,
                       m in make_reader(f).iter_messages(topics=["/thermal/image"])]
    return frames


def test_every_complete_image_of_a_cut_seq_is_imported_and_the_cut_one_reported(samples, tmp_path):
    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "cut.seq"
    seq.write_bytes((fff * 3)[:-3000])  # the last image loses its GPS record and half its calibration
    r = run_cli("import", str(seq), "--root", str(tmp_path / "root"), "--session", "cut", "--json", "--no-analysis")
    assert r.returncode == 1  # something the user did not ask to skip was not imported
    report = json.loads(r.stdout)
    assert report["failed"] == []
    [cut] = report["truncated"]
    assert cut["kept_images"] == 2
    assert cut["expected_bytes"] - cut["got_bytes"] == 3000
    assert "is cut" in cut["error"]
    session = tmp_path / "root" / "sessions" / "cut"
    frames = []
    for seg in sorted(session.glob("*.mcap")):
        with open(seg, "rb") as f:
            frames += [decode_image(m.data)[1].copy() for _, _,
                       m in make_reader(f).iter_messages(topics=["/thermal/image"])]
    assert len(frames) == 2
    ref = json.loads((samples / "flir" / "reference.json").read_text())
    want = next(v["raw_sha256"] for k, v in ref.items() if k.endswith(".fff"))
    assert all(hashlib.sha256(np.ascontiguousarray(f, "<u2").tobytes()).hexdigest() == want for f in frames)


def test_a_single_cut_image_is_still_a_clean_failure(samples, tmp_path):
    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    bad = tmp_path / "cut.fff"
    bad.write_bytes(fff[:-3000])
    r = run_cli("import", str(bad), "--root", str(tmp_path / "root"), "--json", "--no-analysis")
    assert r.returncode == 1
    report = json.loads(r.stdout)
    assert [f["path"] for f in report["failed"]] == [str(bad)]
    assert "cut" in report["failed"][0]["error"]
    assert not (tmp_path / "root" / "sessions").exists() or not any((tmp_path / "root" / "sessions").iterdir())
