"""The ICD section 5 quality report recovers what the simulator injected: NETD, a linear drift,
pattern noise that breaks uniformity, bad pixels, the blackbody's temperature and a linear
response. A session that cannot support a measurement says so. The PDF renders to real pages
(pdftoppm)."""

from __future__ import annotations

import json
import math
import shutil
import subprocess

import pytest
from click.testing import CliRunner

from thermcap.cli import cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.reports.quality import measure_quality

pytest.importorskip("matplotlib", reason="the report's PDF needs matplotlib (pip install 'thermcap[report]')")
SCALE = 0.036  # the simulator's °C per count


def _record(root, name, **kw):
    rec = Recorder(SimSource(width=160, height=128, frames=kw.pop("frames", 180), paced=False, seed=4, **kw), root,
                   session_id=name, analysis=False, recover_leftovers=False)
    assert rec.run().ok
    return rec.session_dir


def _by_name(rep):
    return {m.requirement: m for m in rep.measurements}


def test_a_blackbody_session_gives_back_what_was_injected(tmp_path):
    d = _record(tmp_path, "bb", blackbody_c=35.0, netd_mk=42.0, drift_c_per_h=0.8, bad_pixels=25, frames=300)
    m = _by_name(measure_quality(d))
    # NETD: the injected noise plus the quantisation of rounding to counts (1/12 count²)
    truth = math.sqrt((0.042 / SCALE) ** 2 + 1 / 12) * SCALE * 1000
    assert m["NETD"].value == pytest.approx(truth, rel=0.04) and m["NETD"].passed
    s = m["Temporal stability"]
    assert abs(s.value - 0.8) <= 3 * s.detail["standard_error_c_per_h"] + 0.05 and s.passed
    assert m["Absolute accuracy"].value == pytest.approx(0.8 * 2.5 / 3600, abs=0.01) and m["Absolute accuracy"].passed
    assert m["FPA uniformity"].passed and m["FPA uniformity"].value < 0.1
    bad = m["Bad pixels"]
    assert bad.detail["map_pixels"] == 25 and bad.detail["stuck_pixels"] == 25
    assert bad.value == pytest.approx(25 / (160 * 128) * 100, rel=1e-3) and bad.passed is False  # 0.12 % > 0.1 %
    assert m["Linearity"].passed is None and "three temperatures" in m["Linearity"].method


def test_pattern_noise_fails_uniformity_and_noise_fails_netd(tmp_path):
    d = _record(tmp_path, "noisy", blackbody_c=20.0, netd_mk=80.0, pixel_fpn_mk=1500.0)
    m = _by_name(measure_quality(d))
    assert m["NETD"].passed is False and m["NETD"].value == pytest.approx(80.4, rel=0.05)
    # 1.5 K of pixel FPN on a 1667-count level: about 2.5 % RMS
    assert m["FPA uniformity"].passed is False and 2.0 < m["FPA uniformity"].value < 3.0


def test_linearity_over_reference_sessions_and_the_cli(tmp_path):
    for name, t in (("bb20", 20.0), ("bb50", 50.0), ("bb35", 35.0)):
        _record(tmp_path, name, blackbody_c=t, frames=60, netd_mk=40.0)
    r = CliRunner().invoke(cli, ["report", "quality", "bb35", "--root", str(tmp_path), "--reference", "bb20",
                                 "--reference", "bb50=50", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    lin = next(m for m in out["measurements"] if m["requirement"] == "Linearity")
    assert lin["verdict"] == "pass" and lin["value"] > 0.9999 and len(lin["detail"]["points"]) == 3
    assert lin["detail"]["counts_per_c"] == pytest.approx(1 / SCALE, rel=1e-3)
    r = CliRunner().invoke(cli, ["report", "quality", "bb35", "--root", str(tmp_path), "--reference", "bb20=x"])
    assert r.exit_code == 1 and "SESSION=TEMP_C" in r.output


def test_a_scene_without_a_flat_field_says_what_it_cannot_measure_and_shutter_frames_can(tmp_path):
    plain = _by_name(measure_quality(_record(tmp_path, "scene")))
    for req in ("FPA uniformity", "Temporal stability", "Absolute accuracy", "Linearity"):
        assert plain[req].passed is None and plain[req].value is None and plain[req].method
    assert "view is still" in plain["NETD"].method
    shut = _by_name(measure_quality(_record(tmp_path, "shutter", shutter_every_s=0.5, drift_c_per_h=0.0)))
    assert shut["FPA uniformity"].passed and "shutter" in shut["FPA uniformity"].method
    assert shut["Temporal stability"].value is not None and shut["Absolute accuracy"].passed is None


def test_the_pdf_renders_to_pages(tmp_path):
    if shutil.which("pdftoppm") is None:
        pytest.skip("no pdftoppm here (apt-get install poppler-utils; .ci/run does this)")
    _record(tmp_path, "bb", blackbody_c=30.0, frames=60)
    r = CliRunner().invoke(cli, ["report", "quality", "bb", "--root", str(tmp_path), "--out", str(tmp_path / "r")])
    assert r.exit_code in (0, 1), r.output
    html = (tmp_path / "r" / "quality.html").read_text()
    assert "NETD (ICD 5.2)" in html and "data:image/png;base64," in html
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(tmp_path / "r" / "quality.pdf"), str(tmp_path / "page")],
                   check=True, timeout=60)
    pages = sorted(tmp_path.glob("page*.png"))
    assert len(pages) == 3
    from PIL import Image

    for p in pages:
        img = Image.open(p).convert("L")
        lo, hi = img.getextrema()
        assert hi - lo > 100, f"{p.name} is blank"


def test_the_report_measures_with_the_model_version_and_names_it(tmp_path):
    """Issue 37: the quality report's temperatures come from the version covering each frame. A real
    FLIR T640 frame looked at as a blackbody: the measured mean is flyr's mean at the capture
    emissivity, then at 0.8 after `thermcap radiometry`, and the report names the version."""
    from tests.conftest import SAMPLES, SAMPLES_HOW
    from thermcap.recorder.importers.run import import_paths
    from thermcap.recorder.radiometry.base import model_from_dict
    from thermcap.recorder.radiometry.params import add_version
    from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

    flyr = pytest.importorskip("flyr", reason="flyr is a test dependency (pip install 'thermcap[test]')")
    path = SAMPLES / "flir" / "FLIR_T640.jpg"
    if not path.is_file():
        pytest.skip(f"{path} is not here: {SAMPLES_HOW}")
    import_paths([str(path)], tmp_path, session="t640", analysis=False)
    d = tmp_path / "sessions" / "t640"
    [frame] = list(iter_session_frames(d))
    base = model_from_dict(read_session_meta(d)["radiometric_model"])
    top = (1 << int(getattr(base, "bit_depth", 14) or 14)) - 1
    valid = (frame.pixels > 0) & (frame.pixels < top)

    def reference(emissivity=None):
        th = flyr.unpack(str(path))
        th = th.adjust_metadata(emissivity=emissivity) if emissivity is not None else th
        return float(np.asarray(th.celsius, dtype=np.float64)[valid].mean())

    import numpy as np

    v0 = measure_quality(d, blackbody_c=30.0)
    assert v0.model_versions == [0]
    assert v0.series["mean_c"][0] == pytest.approx(reference(), abs=1e-3)
    add_version(d, base, {"emissivity": 0.8}, who="test", why="a painted surface")
    v1 = measure_quality(d, blackbody_c=30.0)
    assert v1.model_versions == [1] and v1.to_dict()["model_versions"] == [1]
    assert v1.series["mean_c"][0] == pytest.approx(reference(0.8), abs=1e-3)
    assert abs(v1.series["mean_c"][0] - v0.series["mean_c"][0]) > 0.5  # the change is real, not noise
    pinned = measure_quality(d, blackbody_c=30.0, model_version=0)
    assert pinned.model_versions == [0] and pinned.series["mean_c"] == v0.series["mean_c"]
    r = CliRunner().invoke(cli, ["report", "quality", str(d), "--blackbody", "30", "--out", str(tmp_path / "r")])
    assert "model version v1" in r.output, r.output
    assert "model version v1" in (tmp_path / "r" / "quality.html").read_text()
    r = CliRunner().invoke(cli, ["report", "quality", str(d), "--blackbody", "30", "--model-version", "7"])
    assert r.exit_code != 0 and "model version 7" in r.output and "Traceback" not in r.output, r.output
