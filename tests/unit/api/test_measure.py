"""The thermographer's tools checked against plain numpy on real recorded frames: spot, box,
polygon (pixel centres inside, even-odd), line profile, histogram, isotherm, ΔT, and a region's
statistic as a time series (JSON and CSV); bad tools are 400s that say how to write them."""

from __future__ import annotations

import numpy as np
import pytest

from thermcap.recorder.radiometry import DEFAULT_MODEL
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.thermography.measure import Polygon, ToolError, measure, parse_tool

SID = "s-archived"


@pytest.fixture(scope="module")
def temps(root):
    return [np.asarray(DEFAULT_MODEL.to_celsius(f.pixels), dtype=np.float64)
            for f in iter_session_frames(root / "sessions" / SID)]


@pytest.fixture(scope="module")
def masked(root, temps):
    """The reference with the session's bad pixels as NaN, as every °C product gives them (issue 37)."""
    from thermcap.recorder.radiometry.session import read_bad_pixel_map

    mask = read_bad_pixel_map(root / "sessions" / SID)
    assert mask is not None and mask.any()
    out = []
    for t in temps:
        t = t.copy()
        t[mask] = np.nan
        out.append(t)
    return out


def _get(client, path, **q):
    r = client.get(f"/api/v1/sessions/{SID}/{path}", params=q)
    assert r.status_code == 200, r.text
    return r.json()


def test_spot_box_and_delta_t(client, temps):
    t = temps[7]
    body = _get(client, "frames/7/measure", tool=["box:10,20,60,50", "spot:5,6"])
    box, spot = body["measurements"]
    region = t[20:51, 10:61]
    assert box["pixels"] == region.size
    for key, ref in (("max_c", region.max()), ("min_c", region.min()), ("mean_c", region.mean()),
                     ("std_c", region.std())):
        assert box[key] == pytest.approx(ref, abs=1e-4), key
    y, x = np.unravel_index(np.argmax(region), region.shape)
    assert box["max_xy"] == [int(x) + 10, int(y) + 20]
    assert spot["max_c"] == pytest.approx(t[6, 5], abs=1e-4) and spot["pixels"] == 1
    assert body["delta_t_c"]["max"] == pytest.approx(box["max_c"] - spot["max_c"], abs=1e-4)


def _inside(px: float, py: float, pts) -> bool:  # winding number, a different rule-of-thumb than even-odd
    wn = 0
    for (xa, ya), (xb, yb) in zip(pts, pts[1:] + pts[:1], strict=True):
        cross = (xb - xa) * (py - ya) - (px - xa) * (yb - ya)
        if ya <= py < yb and cross > 0:
            wn += 1
        elif yb <= py < ya and cross < 0:
            wn -= 1
    return wn != 0


def test_polygon_against_a_winding_number_reference(client, temps):
    pts = [(12.0, 8.0), (70.0, 15.0), (55.0, 60.0), (20.0, 44.0)]
    t = temps[3]
    ref = np.array([[_inside(x + 0.5, y + 0.5, pts) for x in range(t.shape[1])] for y in range(t.shape[0])])
    m = measure(t, Polygon(tuple(pts)))
    assert m.pixels == int(ref.sum())
    assert m.mean_c == pytest.approx(t[ref].mean(), abs=1e-4) and m.max_c == pytest.approx(t[ref].max(), abs=1e-4)
    body = _get(client, "frames/3/measure", tool=["polygon:" + ",".join(f"{v:g}" for p in pts for v in p)])
    assert body["measurements"][0]["pixels"] == int(ref.sum())


def test_line_histogram_isotherm(client, masked):
    t = masked[11]
    prof = _get(client, "frames/11/profile", line="0,10,100,10")["samples"]
    assert [s["x"] for s in prof] == list(range(101)) and all(s["y"] == 10 for s in prof)
    assert [s["celsius"] if s["celsius"] is not None else -999 for s in prof] == \
        pytest.approx(np.nan_to_num(t[10, :101], nan=-999).tolist(), abs=1e-4)
    h = _get(client, "frames/11/histogram", bins=16, min=0, max=60)
    finite = t[np.isfinite(t)]
    ref, _ = np.histogram(finite, bins=16, range=(0, 60))
    assert h["counts"] == ref.tolist() and h["pixels"] == finite.size < t.size
    full = _get(client, "frames/11/histogram", bins=64)
    assert full["edges_c"][-1] < 549 and full["edges_c"][0] > -40  # no hot or dead pixel in the scale
    iso = _get(client, "frames/11/isotherm", above=25, below=40)
    assert iso["pixels"] == int(((t >= 25) & (t <= 40)).sum())
    png = client.get(f"/api/v1/sessions/{SID}/frames/11/isotherm", params={"above": 25, "format": "png"})
    import imagecodecs

    assert (imagecodecs.png_decode(png.content) > 0).sum() == int((t >= 25).sum())


def test_region_series_over_the_session(client, temps):
    body = _get(client, "series", tool="box:10,20,60,50", stat="max")
    assert [p["frame"] for p in body["points"]] == list(range(len(temps)))
    assert [p["celsius"] for p in body["points"]] == pytest.approx([t[20:51, 10:61].max() for t in temps], abs=1e-4)
    assert all(p["timestamp_ns"] > 0 for p in body["points"])
    csv_text = client.get(f"/api/v1/sessions/{SID}/series",
                          params={"tool": "spot:3,3", "stat": "mean", "start": 5, "end": 9, "format": "csv"}).text
    rows = csv_text.strip().splitlines()
    assert rows[0] == "frame,timestamp_ns,celsius" and [int(r.split(",")[0]) for r in rows[1:]] == [5, 6, 7, 8]


@pytest.mark.parametrize("tool", ["box:1,2,3", "ring:1,2", "spot:9999,1", "box:0,0,5000,5"])
def test_bad_tools_are_400s_that_say_how(client, tool):
    r = client.get(f"/api/v1/sessions/{SID}/frames/0/measure", params={"tool": tool})
    assert r.status_code == 400 and ("use spot:x,y" in r.text or "outside" in r.text), r.text


def test_parse_tool():
    assert parse_tool("box:50,40,10,20") == parse_tool("box:10,20,50,40")  # corners in any order
    with pytest.raises(ToolError):
        parse_tool("polygon:1,2,3,4")
