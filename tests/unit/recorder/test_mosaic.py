"""The proof of the maps on a simulated flight: a camera at known poses over warm targets at
known UTM positions. The mosaic puts every target within one cell of where it is, each cell is
one frame's real measurement (``sources``), hot spots land on the targets, and where the GPS is
off the error stays inside the uncertainty the export reports."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

pytest.importorskip("rasterio", reason="rasterio is in the geo extra (pip install 'thermcap[geo]')")
import rasterio
from affine import Affine
from pyproj import Transformer

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.maps.footprint import utm_epsg
from thermcap.recorder.maps.synthetic import FlightSource, GroundTarget, lawnmower

LAT, LON, H, HFOV = 33.0746, -111.975, 40.0, 2 * math.degrees(math.atan(18 / 58))
EPSG = utm_epsg(LAT, LON)


def _targets() -> list[GroundTarget]:
    e0, n0 = Transformer.from_crs(4326, EPSG, always_xy=True).transform(LON, LAT)
    return [GroundTarget(e0 + de, n0 + dn, 0.6, 45.0) for de, dn in ((3.0, 5.0), (14.0, 20.0), (22.0, 31.0),
                                                                       (8.0, 33.0))]


def _flight(tmp_path, name, pitch=-90.0, gps_error_m=0.0):
    poses = lawnmower(LAT, LON, height_m=H, legs=3, per_leg=4, spacing_m=12.0, hfov_deg=HFOV, pitch_deg=pitch)
    reported = None
    if gps_error_m:
        d = gps_error_m / 111_320.0
        reported = [type(p)(**{**p.to_dict(), "latitude": p.latitude + d}) for p in poses]
    src = FlightSource(poses=poses, targets=_targets(), epsg=EPSG, reported=reported)
    rec = Recorder(src, tmp_path, session_id=name, analysis=True)
    assert rec.run().ok
    return rec.session_dir


def test_the_mosaic_puts_every_target_where_it_is(tmp_path):
    session = _flight(tmp_path, "nadir")
    res = export_session(session, "mosaic", tmp_path / "m")
    assert res["files"] == 3 and not res["refused"], res
    with rasterio.open(tmp_path / "m" / "mosaic.tiff") as m, rasterio.open(tmp_path / "m" / "mosaic.sources.tiff") as s:
        assert m.crs.to_epsg() == EPSG and m.profile["driver"] == "GTiff"
        temps, sources, t = m.read(1), s.read(1), m.transform
        gsd = t.a
        assert set(np.unique(sources)) <= set(range(12)) | {-1}
        assert np.isnan(temps[sources == -1]).all() and not np.isnan(temps[sources >= 0]).any()
        for target in _targets():
            col, row = ~t @ (target.easting, target.northing)
            r0, c0 = int(row), int(col)
            win = temps[max(0, r0 - 30):r0 + 30, max(0, c0 - 30):c0 + 30]
            rr, cc = np.nonzero(win >= 44.0)
            assert len(rr) > 0, "the target is missing from the mosaic"
            cy, cx = rr.mean() + max(0, r0 - 30) + 0.5, cc.mean() + max(0, c0 - 30) + 0.5
            assert math.hypot(cx - col, cy - row) <= 1.0, f"target off by {math.hypot(cx - col, cy - row):.2f} cells"
            assert len(rr) * gsd * gsd == pytest.approx(math.pi * target.radius_m ** 2, rel=0.3)
    info = json.loads((tmp_path / "m" / "mosaic.frames.json").read_text())
    assert len(info["frames"]) == 12 and "nearest" in info["blending"]


def _hot_spot_errors(session, out):
    res = export_session(session, "hotspots", out)
    feats = json.loads((out / "hotspots.geojson").read_text())["features"]
    assert feats, res
    truth = [(t.easting, t.northing) for t in _targets()]
    errs = []
    for f in feats:
        p = f["properties"]
        errs.append((min(math.dist((p["easting"], p["northing"]), tr) for tr in truth), p["uncertainty_m"]))
    return errs


def test_hot_spots_land_on_the_targets_and_a_gps_error_stays_inside_the_uncertainty(tmp_path):
    exact = _hot_spot_errors(_flight(tmp_path, "exact"), tmp_path / "h")
    assert max(e for e, _ in exact) < 0.2
    noisy = _hot_spot_errors(_flight(tmp_path, "noisy", gps_error_m=1.5), tmp_path / "hn")
    assert all(1.0 < e <= u for e, u in noisy), noisy


def test_oblique_frames_are_not_mosaicked_and_still_mapped(tmp_path):
    session = _flight(tmp_path, "oblique", pitch=-60.0)
    res = export_session(session, "mosaic", tmp_path / "m")
    assert res["files"] == 0 and len(res["refused"]) == 12 and "not near nadir" in res["refused"][0]
    errs = _hot_spot_errors(session, tmp_path / "h")
    assert all(e <= u for e, u in errs) and max(e for e, _ in errs) < 1.0  # perspective shifts a blob's centroid


def test_finding_the_targets_against_ground_truth_is_one_command(tmp_path):
    _flight(tmp_path, "truth")
    to_ll = Transformer.from_crs(EPSG, 4326, always_xy=True)
    pts = [to_ll.transform(t.easting, t.northing) for t in _targets()]
    truth = tmp_path / "animals.csv"
    truth.write_text("id,latitude,longitude\n" + "".join(f"a{i},{lat},{lon}\n" for i, (lon, lat) in enumerate(pts)))
    from click.testing import CliRunner

    from thermcap.cli import cli

    r = CliRunner().invoke(cli, ["export", "truth", "--root", str(tmp_path), "--to", "hotspots", "--truth", str(truth),
                                 "--out", str(tmp_path / "h"), "--json"])
    assert r.exit_code == 0, r.output
    report = json.loads(r.output)["truth"]
    assert report["truth"] == 4 and report["matched"] == 4 and report["recall"] == 1.0
    assert all(m["distance_m"] < 0.2 for m in report["matches"])
    assert report["precision"] == round(4 / report["detections"], 4)  # a target seen in two frames counts twice
    bad = tmp_path / "bad.csv"
    bad.write_text("lat,lon\n1,2\n")
    r = CliRunner().invoke(cli, ["export", "truth", "--root", str(tmp_path), "--to", "hotspots", "--truth", str(bad),
                                 "--out", str(tmp_path / "h2")])
    assert r.exit_code == 1 and "bad.csv" in r.output and "latitude,longitude" in r.output


def test_a_flight_across_a_utm_zone_boundary_is_one_mosaic(tmp_path):
    """Legs at 114.0002 W, 114.00007 W and 113.99994 W: two in zone 11, one in zone 12. The
    mosaic is on zone 11's grid, with the zone-12 leg's footprints computed on it."""
    lat, lon = 33.0746, -114.0002
    epsg = utm_epsg(lat, lon)
    e0, n0 = Transformer.from_crs(4326, epsg, always_xy=True).transform(lon, lat)
    targets = [GroundTarget(e0 + de, n0 + dn, 0.6, 45.0) for de, dn in ((3.0, 5.0), (26.0, 20.0), (22.0, 31.0))]
    poses = lawnmower(lat, lon, height_m=H, legs=3, per_leg=4, spacing_m=12.0, hfov_deg=HFOV)
    assert {utm_epsg(p.latitude, p.longitude) for p in poses} == {32611, 32612}
    rec = Recorder(FlightSource(poses=poses, targets=targets, epsg=epsg), tmp_path, session_id="zones", analysis=False)
    assert rec.run().ok
    res = export_session(rec.session_dir, "mosaic", tmp_path / "m")
    assert res["files"] == 3 and not res["refused"], res
    with rasterio.open(tmp_path / "m" / "mosaic.tiff") as m:
        assert m.crs.to_epsg() == 32611
        temps, t = m.read(1), m.transform
        for target in targets:
            col, row = ~t @ (target.easting, target.northing)
            r0, c0 = int(row), int(col)
            win = temps[max(0, r0 - 30):r0 + 30, max(0, c0 - 30):c0 + 30]
            rr, cc = np.nonzero(win >= 44.0)
            assert len(rr) > 0
            cy, cx = rr.mean() + max(0, r0 - 30) + 0.5, cc.mean() + max(0, c0 - 30) + 0.5
            assert math.hypot(cx - col, cy - row) <= 1.0


def test_over_a_dem_hot_spots_land_on_the_targets_and_a_flat_plane_misses_them(tmp_path):
    """A hillside rising 25 % to the east; the drone flies at a constant altitude 40 m above its
    take-off point at the foot of the slope. With the DEM the targets land within 0.3 m; with a
    flat plane at the take-off height (what a file alone says) they are metres off."""
    from thermcap.recorder.maps.terrain import Dem

    e0, n0 = Transformer.from_crs(4326, EPSG, always_xy=True).transform(LON, LAT)
    cell, half, base, slope = 0.5, 150.0, 350.0, 0.25
    n = int(2 * half / cell)
    east = e0 - half + (np.arange(n) + 0.5) * cell
    heights = np.tile(base + slope * np.clip(east - e0, 0, None), (n, 1)).astype(np.float32)
    path = tmp_path / "hill.tif"
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32", crs=f"EPSG:{EPSG}",
                       # from_origin's own arithmetic warns in this rasterio (matmul by `*`)
                       transform=Affine(cell, 0.0, e0 - half, 0.0, -cell, n0 + half)) as dst:
        dst.write(heights, 1)
    dem = Dem.from_file(path)
    altitude = base + 40.0
    poses = []
    for p in lawnmower(LAT, LON, height_m=H, legs=3, per_leg=4, spacing_m=12.0, hfov_deg=HFOV, width=160,
                       height=128):
        ground = dem.elevation_at_lonlat(p.longitude, p.latitude)
        poses.append(type(p)(**{**p.to_dict(), "height_m": altitude - ground, "absolute_altitude_m": altitude}))
    src = FlightSource(poses=poses, targets=_targets(), epsg=EPSG, dem=dem, takeoff_elevation_m=base)
    rec = Recorder(src, tmp_path, session_id="hill", analysis=True)
    assert rec.run().ok

    def errors(**kw):
        res = export_session(rec.session_dir, "hotspots", tmp_path / f"h{len(kw)}", **kw)
        feats = json.loads((tmp_path / f"h{len(kw)}" / "hotspots.geojson").read_text())["features"]
        assert feats, res
        truth = [(t.easting, t.northing) for t in _targets()]
        return [min(math.dist((f["properties"]["easting"], f["properties"]["northing"]), tr) for tr in truth)
                for f in feats]

    on_dem = errors(dem=path)
    assert max(on_dem) < 0.3, on_dem
    flat = errors()
    assert max(flat) > 1.0, flat
