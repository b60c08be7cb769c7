"""Issue 37: the storage audit, checked figure by figure against a hand computation. It had
averaged stills with video (11 imported images moved HDF5 from 33.0 to 22.0 GiB per recorded
hour), recommended HDF5 for single images where it is the largest, left unarchived sessions out
without a word, and given a "$ total" without saying what it assumed."""

from __future__ import annotations

import json

import pytest

from tests.conftest import SAMPLES, SAMPLES_HOW, run_cli
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.importers.run import import_paths

GIB = 1024**3


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("audit")
    Recorder(SimSource(width=160, height=128, frames=120, paced=False, seed=2), root, session_id="video",
             analysis=False).run()
    archive_session(root / "sessions" / "video", ["png16", "hdf5"])
    for name in ("FLIR_E40.jpg", "FLIR_T640.jpg"):
        if not (SAMPLES / "flir" / name).is_file():
            pytest.skip(f"{SAMPLES / 'flir' / name} is not here: {SAMPLES_HOW}")
    import_paths([str(SAMPLES / "flir" / "FLIR_E40.jpg")], root, session="stills", analysis=False)
    archive_session(root / "sessions" / "stills", ["png16", "hdf5"])
    Recorder(SimSource(width=64, height=48, frames=10, paced=False, seed=3), root, session_id="pending",
             analysis=False).run()
    return root


def _manifest(root, sid):
    return json.loads((root / "sessions" / sid / "archive" / "manifest.json").read_text())


def _audit(root, *extra):
    r = run_cli("audit", "--root", str(root), "--json", *extra)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_stills_and_video_are_never_averaged(root):
    rep = _audit(root)
    groups = {g["kind"]: g for g in rep["groups"]}
    assert set(groups) == {"continuous", "stills"}
    video, stills = groups["continuous"], groups["stills"]
    m = _manifest(root, "video")
    t = m["frames"]["timestamps_ns"]
    hours = ((t[-1] - t[0]) / 1e9 + 1 / 60) / 3600  # the sim's 60 fps
    for fid in ("png16", "hdf5"):
        by_hand = m["formats"][fid]["bytes"] / GIB / hours
        assert video["formats"][fid]["gib_per_recorded_hour"] == pytest.approx(by_hand, rel=1e-3)
    s = _manifest(root, "stills")
    for fid in ("png16", "hdf5"):
        assert stills["formats"][fid]["bytes_per_image"] == s["formats"][fid]["bytes"]
        assert "gib_per_recorded_hour" not in stills["formats"][fid]
    assert stills["hours"] is None and stills["frames"] == 1


def test_each_group_gets_its_own_recommendation_and_the_rule(root):
    rep = _audit(root)
    for g in rep["groups"]:
        verified = {k: v["bytes"] for k, v in g["formats"].items() if k != "mcap"}
        assert g["recommended_format"] == min(verified, key=verified.get)
    stills = next(g for g in rep["groups"] if g["kind"] == "stills")
    assert stills["recommended_format"] == "png16"  # hdf5 is the largest for a single image
    assert "per image for stills" in rep["recommendation_rule"]


def test_unarchived_sessions_are_named_as_left_out(root):
    rep = _audit(root)
    assert [x["session"] for x in rep["left_out"]] == ["pending"]
    assert "not archived" in rep["left_out"][0]["why"]
    plain = run_cli("audit", "--root", str(root)).stdout
    assert "left out: pending" in plain


def test_the_projection_says_what_it_assumes_and_gives_both_figures(root):
    rep = _audit(root, "--project-cameras", "10", "--project-hours", "8", "--project-days", "30",
                 "--project-retention-days", "10")
    [p] = rep["projection"].values()
    assert "10 cameras x 8 h a day" in p["assumes"] and "after 10 days" in p["assumes"]
    video = next(g for g in rep["groups"] if g["kind"] == "continuous")
    bph = video["formats"]["png16"]["bytes"] / video["hours"]
    per_day = bph * 10 * 8
    stored = per_day * 10
    c = p["formats"]["png16"]["cost"]["s3-standard"]
    assert c["monthly_at_end"] == pytest.approx(stored / GIB * 0.023, abs=0.01)
    gib_days = (per_day * 10 * 10 / 2 + per_day * 10 * 20) / GIB
    assert c["storage_total"] == pytest.approx(gib_days / (365 / 12) * 0.023, abs=0.01)


def test_the_default_output_is_an_aligned_table(root):
    out = run_cli("audit", "--root", str(root)).stdout.splitlines()
    header, rule = out[0], out[1]
    assert header.split()[:3] == ["sensor", "kind", "format"] and set(rule.replace(" ", "")) == {"-"}
    rows = [line for line in out[2:] if line.strip() and not line.startswith(("rule", "left out"))]
    assert "**" not in "\n".join(out)
    ends = {len(line.rstrip()) for line in rows if "recommended" not in line and "not every" not in line}
    assert len(rows) >= 4 and len(ends) <= 2  # columns line up
