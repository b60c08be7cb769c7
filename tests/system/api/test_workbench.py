"""The workbench on the session page, in a real headless Chromium: a box drawn with the mouse
reads what the API measures for it, ΔT between two tools, the histogram and the isotherm draw,
the arrow keys step frames, play advances at the recorded rate, and the region series runs.
The screenshot is kept in docs/ and looked at."""

from __future__ import annotations

import json
import os
import urllib.request
from pathlib import Path

from tests.support.cdp import Browser

DOCS = Path(__file__).resolve().parents[3] / "docs"


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


def _rect(browser: Browser) -> list[float]:
    return browser.eval("(() => { const r = document.getElementById('overlay').getBoundingClientRect();"
                        " return [r.left, r.top, r.width, r.height]; })()")


def test_tools_histogram_isotherm_keys_play_and_series(browser, server):
    sid = "s-crossover"
    browser.open(f"{server.url}/ui/sessions/{sid}")
    browser.pump(1.0)
    left, top, w, h = _rect(browser)
    session = _get(f"{server.url}/api/v1/sessions/{sid}")
    sx, sy = w / session["width"], h / session["height"]
    browser.eval("(() => { const s = document.getElementById('tool'); s.value = 'box'; })()")
    browser.drag(left + 20 * sx + 1, top + 60 * sy + 1, left + 80 * sx + 1, top + 100 * sy + 1)
    browser.pump(1.5)
    tools = browser.eval("workbench.state.tools.map(t => [t.kind, Math.round(t.x0), Math.round(t.y0),"
                         " Math.round(t.x1), Math.round(t.y1)])")
    assert tools == [["box", 20, 60, 80, 100]], tools
    browser.eval("workbench.addTool('spot:40,20')")
    browser.pump(1.5)
    frame = browser.eval("workbench.state.frame")
    want = _get(f"{server.url}/api/v1/sessions/{sid}/frames/{frame}/measure?tool=box:20,60,80,100&tool=spot:40,20")
    cells = browser.eval("[...document.querySelectorAll('#readouts tr')].map(r => r.textContent)")
    assert any(str(want["measurements"][0]["max_c"]) in c for c in cells), (cells, want)
    assert any(f"max {want['delta_t_c']['max']} °C" in c for c in cells), cells
    # the histogram of the box and an isotherm overlay
    assert "in #1" in browser.eval("document.getElementById('histinfo').textContent")
    hist_drawn = browser.eval("(() => { const c = document.getElementById('hist'); const d = c.getContext('2d')"
                              ".getImageData(0, 0, c.width, c.height).data; let n = 0;"
                              " for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n; })()")
    assert hist_drawn > 200
    browser.eval("(() => { const c = document.getElementById('iso'); c.checked = true;"
                 " document.getElementById('isoT').value = 17; c.dispatchEvent(new Event('change')); })()")
    browser.pump(1.5)
    iso = browser.eval("document.getElementById('isoinfo').textContent")
    want_iso = _get(f"{server.url}/api/v1/sessions/{sid}/frames/{frame}/isotherm?above=17")
    assert iso.startswith(f"{want_iso['pixels']} px above 17"), iso
    # arrow keys step, play advances at the recorded rate
    browser.key("ArrowRight", "ArrowRight", 39)
    browser.pump(1.0)
    assert browser.eval("workbench.state.frame") == frame + 1
    browser.key("ArrowLeft", "ArrowLeft", 37)
    browser.pump(1.0)
    assert browser.eval("workbench.state.frame") == frame
    browser.eval("document.getElementById('play').click()")
    browser.pump(1.0)
    browser.eval("document.getElementById('play').click()")  # pause
    moved = browser.eval("workbench.state.frame") - frame
    fps = (session["frames"] - 1) / ((session["end_ns"] - session["start_ns"]) / 1e9)
    assert 1 <= moved <= fps * 1.6, (moved, fps)  # never ahead of the recorded clock
    # the region series under the scrubber
    browser.eval("document.getElementById('seriesbtn').click()")
    browser.pump(3.0)
    info = browser.eval("document.getElementById('seriesinfo').textContent")
    assert info.startswith("max of #1 over"), info
    assert browser.exceptions == [], browser.exceptions
    if os.environ.get("THERMCAP_WRITE_DOCS"):  # refresh the README's screenshot by hand
        browser.screenshot(DOCS / "workbench.png")
