"""A °C scale wherever a person looks: the preview draws its colour bar and carries its range
(headers and PNG text), in frame, session or fixed mode; heatmap exports and overlays do the
same; the session page says when a session has no temperatures instead of failing."""

from __future__ import annotations

import json

import imagecodecs
import numpy as np
import pytest

from tests.support.api_data import H, W
from thermcap.recorder.exports.colorbar import TemperatureRange, add_colorbar, png_text
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.exports.render import palette
from thermcap.recorder.radiometry import DEFAULT_MODEL
from thermcap.recorder.storage.reader import iter_session_frames


def _url(n, **q):
    return f"/api/v1/sessions/s-archived/frames/{n}?format=preview&" + "&".join(f"{k}={v}" for k, v in q.items())


def test_the_preview_draws_its_scale_and_says_its_range(client, root):
    r = client.get(_url(5))
    assert r.status_code == 200
    img = imagecodecs.png_decode(r.content)
    assert img.shape[0] == H and img.shape[1] > W  # the bar is drawn beside the picture
    text = png_text(r.content)
    assert text["thermcap:units"] == "degC" and text["thermcap:range_mode"] == "frame"
    lo, hi = float(r.headers["X-Range-Min"]), float(r.headers["X-Range-Max"])
    assert (lo, hi) == (float(text["thermcap:range_min"]), float(text["thermcap:range_max"]))
    frame = list(iter_session_frames(root / "sessions" / "s-archived"))[5].pixels
    temps = DEFAULT_MODEL.to_celsius(frame)
    assert lo == pytest.approx(np.percentile(temps, 0.5), abs=1e-3)
    assert hi == pytest.approx(np.percentile(temps, 99.5), abs=1e-3)
    bare = client.get(_url(5, colorbar="false"))
    assert imagecodecs.png_decode(bare.content).shape[:2] == (H, W)
    assert png_text(bare.content)["thermcap:range_min"] == text["thermcap:range_min"]


def test_session_and_fixed_scales(client):
    a, b = client.get(_url(1, range="session")), client.get(_url(50, range="session"))
    assert a.headers["X-Range-Mode"] == "session"
    assert (a.headers["X-Range-Min"], a.headers["X-Range-Max"]) == (b.headers["X-Range-Min"], b.headers["X-Range-Max"])
    f = client.get(_url(1, range="fixed", min=-10, max=60))
    assert (f.headers["X-Range-Min"], f.headers["X-Range-Max"], f.headers["X-Range-Mode"]) == \
        ("-10.0000", "60.0000", "fixed")
    assert client.get(_url(1, range="fixed")).status_code == 400
    assert client.get(_url(1, min=5, max=2)).status_code == 400


def test_the_session_says_whether_it_has_temperatures(client):
    assert client.get("/api/v1/sessions/s-archived").json()["temperature"] == {"available": True, "why": None}


def test_heatmap_export_carries_its_scale(root, tmp_path):
    session = root / "sessions" / "s-crossover"
    res = export_session(session, "heatmap-png", tmp_path / "s")
    files = sorted((tmp_path / "s").glob("*.png"))
    assert res["files"] == len(files) == 120
    first, last = png_text(files[0].read_bytes()), png_text(files[-1].read_bytes())
    assert first["thermcap:range_mode"] == "session" and first["thermcap:range_min"] == last["thermcap:range_min"]
    assert imagecodecs.png_decode(files[0].read_bytes()).shape[1] > W
    export_session(session, "heatmap-png", tmp_path / "f", range_mode="fixed", t_min=0, t_max=30, colorbar=False)
    one = sorted((tmp_path / "f").glob("*.png"))[0].read_bytes()
    assert png_text(one)["thermcap:range_max"] == "30.0000"
    assert imagecodecs.png_decode(one).shape[1] == W


def test_the_bar_runs_from_the_coldest_colour_at_the_bottom_to_the_hottest_at_the_top():
    lut = palette("turbo")
    out = add_colorbar(np.zeros((240, 320, 3), np.uint8), TemperatureRange(-5.0, 35.0), lut)
    bar = out[:, 320 + 6:320 + 6 + 4].reshape(240, -1, 3)[:, 0]  # a column inside the bar
    colours = {tuple(c) for c in lut}
    coloured = [tuple(c) for c in bar if tuple(c) in colours]  # not the background, ticks or the unit
    assert coloured[0] == tuple(lut[255]) and coloured[-1] == tuple(lut[0])
    label_pixels = out[:, 320 + 6 + 12 + 6:]
    assert (label_pixels == 235).any()  # tick labels drawn


def test_each_session_gets_a_foxglove_layout_that_fits_its_counts(client, root):
    layout = client.get("/api/v1/sessions/s-archived/foxglove-layout").json()
    image = layout["configById"]["Image!thermal"]["imageMode"]
    frames = [f.pixels for f in iter_session_frames(root / "sessions" / "s-archived")]
    lo, hi = int(np.percentile(np.stack(frames), 0.5)), int(np.percentile(np.stack(frames), 99.5))
    assert abs(image["minValue"] - lo) < 60 and abs(image["maxValue"] - hi) < 60, (image, lo, hi)
    assert image["maxValue"] < 4000  # not the washed-out 0..16383 of one fixed layout
    assert image["annotations"] == {"/thermal/annotations": {"visible": True}}
    written = json.loads((root / "sessions" / "s-archived" / "foxglove_layout.json").read_text())
    w = written["configById"]["Image!thermal"]["imageMode"]
    assert abs(w["minValue"] - lo) < 60 and abs(w["maxValue"] - hi) < 60
