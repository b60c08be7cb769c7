"""Every control on the session page works or says why not, in a real headless Chromium driven
over the DevTools protocol: the colour scale shows the preview's range and follows the range
mode; on a DJI session without DJI's SDK, moving over the image says why there is no reading
(no unhandled promise rejection) and the °C TIFF link is disabled with the reason."""

from __future__ import annotations

import pytest

from tests.conftest import SAMPLES, SAMPLES_HOW, ApiServer
from tests.support.cdp import Browser
from thermcap.recorder.importers.run import import_paths


@pytest.fixture(scope="module")
def dji_server(tmp_path_factory):
    sample = SAMPLES / "dji" / "DJI_H20T.jpg"
    if not sample.is_file():
        pytest.skip(f"{sample} is not here: {SAMPLES_HOW}")
    root = tmp_path_factory.mktemp("djiroot")
    import_paths([str(sample)], root, session="h20t", dji_sdk=None)
    s = ApiServer(root)
    yield s
    s.stop()


def _hover(browser: Browser) -> str:
    box = browser.eval("(() => { const r = document.getElementById('img').getBoundingClientRect();"
                       " return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    browser.move_mouse(*box)
    browser.pump(1.5)
    return browser.eval("document.getElementById('temp').textContent")


def test_the_scale_follows_the_range_mode(browser, server):
    browser.open(f"{server.url}/ui/sessions/s-archived")
    browser.pump(1.0)
    lo, hi = browser.eval("[document.getElementById('lo').textContent, document.getElementById('hi').textContent]")
    assert lo.endswith("°C") and hi.endswith("°C") and float(lo.split()[0]) < float(hi.split()[0])
    assert browser.eval("document.getElementById('mode').textContent") == "(frame scale)"
    browser.eval("(() => { const s = document.getElementById('range'); s.value = 'fixed';"
                 " s.dispatchEvent(new Event('change')); })()")
    browser.pump(1.5)
    assert browser.eval("document.getElementById('mode').textContent") == "(fixed scale)"
    assert browser.eval("document.getElementById('lo').textContent") == "0.0 °C"
    assert browser.eval("document.getElementById('hi').textContent") == "50.0 °C"
    reading = _hover(browser)
    assert "°C" in reading and "counts" in reading, reading
    assert browser.exceptions == [], browser.exceptions


def test_a_dji_session_without_the_sdk_says_why_and_raises_nothing(browser, dji_server):
    browser.exceptions.clear()
    browser.open(f"{dji_server.url}/ui/sessions/h20t")
    browser.pump(1.0)
    reading = _hover(browser)
    assert "no temperature here" in reading and "DJI Thermal SDK" in reading, reading
    link = browser.eval("(() => { const a = [...document.querySelectorAll('#framelinks a')]"
                        ".find(a => a.textContent === '°C TIFF'); return [a.className, a.getAttribute('href')]; })()")
    assert link == ["off", None]
    assert browser.eval("document.getElementById('lo').textContent").endswith("counts")
    assert browser.exceptions == [], browser.exceptions
