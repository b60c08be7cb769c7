"""Schemathesis over the OpenAPI schema (no 500s), and the browser view in headless Chromium."""

from __future__ import annotations

import shutil
import subprocess
import tempfile

import pytest

CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars", "--window-size=1280,900", "--virtual-time-budget=15000"]


def test_schemathesis_finds_no_server_errors(server, tmp_path):
    st = shutil.which("schemathesis") or shutil.which("st")
    if not st:
        pytest.skip("schemathesis is not installed (it is in the test extras)")
    r = subprocess.run([st, "run", f"{server.url}/openapi.json", "--checks", "not_a_server_error",
                        "--max-examples", "20", "--request-timeout", "30", "--no-color"],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)  # its cache stays out of the repo
    assert r.returncode == 0, r.stdout[-4000:]
    assert "passed" in r.stdout


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return shutil.which(name)
    pytest.skip("no Chromium here (apt-get install chromium; .ci/run does this)")


def test_session_page_renders_in_headless_chromium(server, tmp_path):
    chromium = _chromium()
    url = f"{server.url}/ui/sessions/s-archived"
    with tempfile.TemporaryDirectory() as profile:
        dom = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", url],
                             capture_output=True, text=True, timeout=120).stdout
    assert 'data-ready="1"' in dom, dom[-2000:]
    assert "frame 0 / 59" in dom
    assert "s-archived" in dom
    assert "/frames/0?format=celsius-tiff" in dom  # per-frame links
    assert "?format=dji-rjpeg" not in dom  # not a DJI session
    assert 'src="blob:' in dom  # the colour preview was fetched and shown
    out = tmp_path / "session.png"
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--screenshot={out}", url],
                       capture_output=True, timeout=120)
    assert out.is_file()
    assert out.stat().st_size > 10_000
    import imagecodecs
    import numpy as np

    img = imagecodecs.png_decode(out.read_bytes())
    assert img.shape[0] >= 800
    assert img.shape[1] >= 1200
    assert len(np.unique(img.reshape(-1, img.shape[-1])[:, :3],
                         axis=0)) > 50  # a rendered thermal image, not a blank page


def test_sessions_page_lists_sessions_in_chromium(server):
    chromium = _chromium()
    with tempfile.TemporaryDirectory() as profile:
        dom = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", server.url + "/"],
                             capture_output=True, text=True, timeout=120).stdout
    assert "/ui/sessions/s-crossover" in dom
    assert "/ui/sessions/s-mcap-only" in dom
