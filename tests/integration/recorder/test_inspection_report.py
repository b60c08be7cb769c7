"""The inspection report's numbers are recomputed from the archive by ``report verify``: they
hold after a re-parameterisation (each names its model version) and after --delete-source (the
archive is the source), and a changed number, a swapped JSON twin or changed counts are caught.
Each number is checked against a numpy reference on the counts."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from thermcap.cli import cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames

pytest.importorskip("matplotlib", reason="the report's PDF needs matplotlib (pip install 'thermcap[report]')")


def _run(*args):
    return CliRunner().invoke(cli, list(args))


@pytest.fixture
def reported(tmp_path):
    rec = Recorder(SimSource(width=320, height=256, frames=90, paced=False, seed=2), tmp_path, session_id="s",
                   analysis=True, recover_leftovers=False)
    assert rec.run().ok
    r = _run("report", "inspection", "s", "--root", str(tmp_path), "--out", str(tmp_path / "r"), "--json")
    assert r.exit_code == 0, r.output
    return tmp_path, json.loads(r.output)


def test_every_number_is_the_counts_own_and_verify_holds(reported):
    root, rep = reported
    assert len(rep["findings"]) >= 2
    frames = {f.index: f.pixels for f in iter_session_frames(root / "sessions" / "s")}
    for f in rep["findings"]:
        temps = frames[f["frame"]].astype(np.float64) * 0.036 - 40.0  # the simulator's linear model
        x0, y0, x1, y1 = f["box"]
        assert f["max_c"] == pytest.approx(temps[y0:y1 + 1, x0:x1 + 1].max(), abs=1e-3)
        ring = np.zeros(temps.shape, bool)
        ring[max(0, y0 - 10):y1 + 11, max(0, x0 - 10):x1 + 11] = True
        ring[max(0, y0 - 3):y1 + 4, max(0, x0 - 3):x1 + 4] = False
        assert f["reference_c"] == pytest.approx(np.median(temps[ring]), abs=1e-3)
        assert f["delta_t_c"] == pytest.approx(f["max_c"] - f["reference_c"], abs=2e-3)
        assert f["model_version"] == 0 and len(f["frame_sha256"]) == 64
    r = _run("report", "verify", str(root / "r" / "inspection.pdf"), "--root", str(root))
    assert r.exit_code == 0 and "the report holds" in r.output, r.output


def test_a_real_flir_image_holds_after_a_reparameterisation(tmp_path):
    """FLIR_T640 (Planck): a report names model version 0; after emissivity 0.8 is recorded as
    version 1 it still verifies, and a new report names version 1 and other temperatures."""
    from tests.conftest import SAMPLES, SAMPLES_HOW

    sample = SAMPLES / "flir" / "FLIR_T640.jpg"
    if not sample.is_file():
        pytest.skip(f"{sample} is not here: {SAMPLES_HOW}")
    assert _run("import", str(sample), "--root", str(tmp_path), "--session", "t640").exit_code == 0
    r = _run("report", "inspection", "t640", "--root", str(tmp_path), "--out", str(tmp_path / "a"), "--json")
    assert r.exit_code == 0, r.output
    before = json.loads(r.output)["findings"]
    assert before and all(f["model_version"] == 0 for f in before)
    r = _run("radiometry", "t640", "--root", str(tmp_path), "--set", "emissivity=0.8", "--why", "painted surface")
    assert r.exit_code == 0, r.output
    r = _run("report", "verify", str(tmp_path / "a" / "inspection.pdf"), "--root", str(tmp_path))
    assert r.exit_code == 0 and "model version 0" in r.output, r.output
    r = _run("report", "inspection", "t640", "--root", str(tmp_path), "--out", str(tmp_path / "b"), "--json")
    after = json.loads(r.output)["findings"]
    assert all(f["model_version"] == 1 for f in after)
    assert after[0]["max_c"] != before[0]["max_c"]  # emissivity 0.8 reads hotter surfaces


def test_it_still_holds_after_delete_source(reported):
    root, _ = reported
    from thermcap.archive.archiver import archive_session

    archive_session(root / "sessions" / "s", ["png16"], delete_source=True)
    assert not list((root / "sessions" / "s").glob("*.mcap"))
    r = _run("report", "verify", str(root / "r" / "inspection.json"), "--root", str(root), "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["holds"]


def test_a_changed_number_or_a_swapped_twin_is_caught(reported):
    root, _ = reported
    twin = root / "r" / "inspection.json"
    doc = json.loads(twin.read_text())
    doc["findings"][0]["max_c"] += 0.5
    tampered = root / "tampered.json"
    tampered.write_text(json.dumps(doc))
    r = _run("report", "verify", str(tampered), "--root", str(root))
    assert r.exit_code == 1 and "DIFFERS" in r.output and "max_c" in r.output
    twin.write_text(json.dumps(doc, indent=2) + "\n")  # the PDF's twin swapped for another
    r = _run("report", "verify", str(root / "r" / "inspection.pdf"), "--root", str(root))
    assert r.exit_code == 1 and "not the JSON this PDF was made with" in r.output
    r = _run("report", "verify", str(root / "r" / "missing.json"), "--root", str(root))
    assert r.exit_code == 2


def test_the_pdf_renders_to_pages(reported):
    root, rep = reported
    if shutil.which("pdftoppm") is None:
        pytest.skip("no pdftoppm here (apt-get install poppler-utils; .ci/run does this)")
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(root / "r" / "inspection.pdf"), str(root / "page")],
                   check=True, timeout=60)
    pages = sorted(root.glob("page*.png"))
    assert len(pages) == len(rep["findings"]) + 2  # summary, a page per finding, provenance
    from PIL import Image

    for p in pages:
        lo, hi = Image.open(p).convert("L").getextrema()
        assert hi - lo > 100, f"{p.name} is blank"


def test_listed_bad_pixels_are_in_no_number(tmp_path):
    """Issue 37: the report took a box's max and its ring's median over every pixel, so a listed
    hot pixel (549.8 °C on the simulator) inside a box became the finding's temperature. With
    bad pixels dense enough to fall in the boxes, every number is the good pixels' own."""
    from thermcap.recorder.radiometry.session import read_bad_pixel_map

    rec = Recorder(SimSource(width=320, height=256, frames=60, paced=False, seed=4, bad_pixels=2500), tmp_path,
                   session_id="b", analysis=True, recover_leftovers=False)
    assert rec.run().ok
    r = _run("report", "inspection", "b", "--root", str(tmp_path), "--out", str(tmp_path / "r"), "--json")
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    session = tmp_path / "sessions" / "b"
    mask = read_bad_pixel_map(session)
    frames = {f.index: f.pixels for f in iter_session_frames(session)}
    hit = 0
    for f in rep["findings"]:
        temps = frames[f["frame"]].astype(np.float64) * 0.036 - 40.0
        temps[mask] = np.nan
        x0, y0, x1, y1 = f["box"]
        hit += int(mask[y0:y1 + 1, x0:x1 + 1].any())
        assert f["max_c"] == pytest.approx(np.nanmax(temps[y0:y1 + 1, x0:x1 + 1]), abs=1e-3)
        ring = np.zeros(temps.shape, bool)
        ring[max(0, y0 - 10):y1 + 11, max(0, x0 - 10):x1 + 11] = True
        ring[max(0, y0 - 3):y1 + 4, max(0, x0 - 3):x1 + 4] = False
        assert f["reference_c"] == pytest.approx(np.nanmedian(temps[ring]), abs=1e-3)
    assert hit, "no listed bad pixel fell in a box: the test proves nothing"
    r = _run("report", "verify", str(tmp_path / "r" / "inspection.json"), "--root", str(tmp_path))
    assert r.exit_code == 0 and "the report holds" in r.output, r.output
