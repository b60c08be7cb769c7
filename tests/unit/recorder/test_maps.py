"""Footprints on a flat ground plane from a camera's pose: the geometry checked against what it
must be (2·h·tan(FOV/2) at nadir, the yaw's direction on the map, corners that project back to
the image's corners), honest refusals near the horizon, uncertainty that grows when oblique."""

from __future__ import annotations

import math

import numpy as np
import pytest

from thermcap.recorder.maps.footprint import FootprintRefused, footprint, ground_to_pixel, utm_epsg
from thermcap.recorder.maps.pose import CameraPose, PoseMissing, pose_from_vendor

pytest.importorskip("pyproj", reason="pyproj is in the geo extra (pip install 'thermcap[geo]')")


def _pose(pitch=-90.0, yaw=0.0, roll=0.0, h=100.0, lat=53.4489, lon=-2.815, hfov=34.5, w=640, ht=512):
    return CameraPose(lat, lon, h, pitch, yaw, roll, hfov, w, ht, "test")


def test_nadir_footprint_is_two_h_tan_half_fov_and_an_affine_map():
    fp = footprint(_pose())
    assert fp.nadir and fp.epsg == 32630
    assert fp.width_m == pytest.approx(2 * 100 * math.tan(math.radians(34.5 / 2)), rel=1e-6)
    assert fp.gsd_m == pytest.approx(fp.width_m / 640, rel=1e-3)
    e0, dec, der, n0, dnc, dnr = fp.geotransform()
    centre = (e0 + dec * 320 + der * 256, n0 + dnc * 320 + dnr * 256)
    assert centre == pytest.approx(fp.camera_en, abs=1e-3)  # the image centre is under the camera
    assert dnr < 0 and abs(der) < 0.02 * abs(dec)  # north up: rows go south; yaw 0 is near grid north


def test_yaw_turns_the_footprint_on_the_map():
    fp = footprint(_pose(yaw=90.0))  # the top of the image faces east, its right side south
    (e0, n0), (e1, n1) = fp.corners_en[0], fp.corners_en[1]
    assert n1 - n0 == pytest.approx(-fp.width_m, rel=0.02) and abs(e1 - e0) < 0.02 * fp.width_m


def test_corners_project_back_to_the_image_corners():
    for pose in (_pose(), _pose(pitch=-50.0, yaw=30.0, roll=2.0)):
        fp = footprint(pose)
        want = [(0, 0), (640, 0), (640, 512), (0, 512)]
        for (e, n), (c, r) in zip(fp.corners_en, want, strict=True):
            got = ground_to_pixel(fp, e, n)
            assert got is not None and got == pytest.approx((c, r), abs=1e-3)


def test_oblique_is_a_trapezoid_with_more_uncertainty():
    nadir, oblique = footprint(_pose()), footprint(_pose(pitch=-45.0))
    assert not oblique.nadir and oblique.notes
    near = math.dist(oblique.corners_en[3], oblique.corners_en[2])
    far = math.dist(oblique.corners_en[0], oblique.corners_en[1])
    assert far > 1.5 * near  # the far edge is wider
    assert oblique.uncertainty_m > nadir.uncertainty_m > 2.0  # at least the GPS's own 2 m


def test_near_the_horizon_is_refused_with_the_reason():
    with pytest.raises(FootprintRefused, match="horizon"):
        footprint(_pose(pitch=-10.5))  # the H20T sample: the top edge looks above the horizon
    with pytest.raises(FootprintRefused, match="horizon"):
        footprint(_pose(pitch=0.0))


def test_utm_zones():
    assert utm_epsg(53.4, -2.8) == 32630
    assert utm_epsg(-33.9, 18.4) == 32734
    assert utm_epsg(40.56, -79.76) == 32617


def test_pose_from_what_the_file_says():
    xmp = {"GpsLatitude": "40.5637", "GpsLongitude": "-79.7650", "RelativeAltitude": "+16.508",
           "AbsoluteAltitude": "+221.404", "GimbalPitchDegree": "-90.00", "GimbalYawDegree": "+32.50",
           "GimbalRollDegree": "+0.00"}
    pose = pose_from_vendor({"xmp_drone_dji": xmp, "exif_focal_length_35mm": 58}, 640, 512)
    assert pose.hfov_deg == pytest.approx(34.5, abs=0.05)  # exiftool's "Field Of View: 34.5 deg"
    assert pose.height_m == pytest.approx(16.508)
    assert pose_from_vendor({"xmp_drone_dji": xmp, "exif_focal_length_35mm": 58}, 640, 512,
                            ground_elevation_m=200.0).height_m == pytest.approx(21.404)
    with pytest.raises(PoseMissing, match="no position"):
        pose_from_vendor({}, 640, 512)
    with pytest.raises(PoseMissing, match="attitude"):
        pose_from_vendor({"gps": {"latitude": 53.4, "longitude": -2.8}}, 640, 512)
    with pytest.raises(PoseMissing, match="field of view"):
        pose_from_vendor({"xmp_drone_dji": xmp}, 640, 512)


def test_a_flir_drone_cameras_xmp_gives_its_pose():
    """FLIR Vue/Duo Pro R: Pix4D's Camera:Pitch (0 = nadir) as rationals, FLIR:MAVRelativeAltitude,
    and the thermal lens's FieldOfView from CameraInfo before any focal-length guess."""
    vendor = {"gps": {"latitude": 53.449, "longitude": -2.815, "altitude_m": 81.0, "source": "FLIR GPSInfo"},
              "xmp_camera": {"Yaw": "3250/100", "Pitch": "1000/100", "Roll": "-50/100"},
              "xmp_flir": {"MAVRelativeAltitude": "40500/1000"}, "field_of_view_deg": 45.0,
              "exif_focal_length_35mm": 58}
    pose = pose_from_vendor(vendor, 640, 512)
    assert (pose.pitch_deg, pose.yaw_deg, pose.roll_deg) == (-80.0, 32.5, -0.5)
    assert pose.height_m == pytest.approx(40.5) and pose.hfov_deg == 45.0 and "FieldOfView" in pose.fov_source
    assert pose_from_vendor(vendor, 640, 512, ground_elevation_m=41.0).height_m == pytest.approx(40.0)
    nadir = footprint(pose_from_vendor({**vendor, "xmp_camera": {"Yaw": "0/100", "Pitch": "0/100"}}, 640, 512))
    assert nadir.nadir and nadir.width_m == pytest.approx(2 * 40.5 * math.tan(math.radians(22.5)), rel=1e-6)
    with pytest.raises(PoseMissing, match="attitude"):  # a Duo Pro R FFF: a position, no attitude
        pose_from_vendor({"gps": vendor["gps"], "field_of_view_deg": 45.0}, 640, 512)


def _plane_dem(pose, slope, base=100.0, half=300.0, cell=1.0):
    """A DEM on the camera's UTM grid: z = base + slope * (easting - the camera's easting)."""
    from pyproj import CRS, Transformer

    from thermcap.recorder.maps.terrain import Dem

    epsg = utm_epsg(pose.latitude, pose.longitude)
    ce, cn = Transformer.from_crs(4326, epsg, always_xy=True).transform(pose.longitude, pose.latitude)
    n = int(2 * half / cell)
    east = ce - half + (np.arange(n) + 0.5) * cell
    heights = np.tile(base + slope * (east - ce), (n, 1))
    return Dem(heights, (ce - half, cell, 0.0, cn + half, 0.0, -cell), CRS.from_epsg(epsg).to_wkt(), "plane.tif"), ce


def test_over_a_dem_each_corner_lands_on_the_terrain():
    flat = _pose(h=100.0)
    dem, ce = _plane_dem(flat, slope=0.2)  # rising to the east
    vendor = {"xmp_drone_dji": {"GpsLatitude": str(flat.latitude), "GpsLongitude": str(flat.longitude),
                                "AbsoluteAltitude": "+200.0", "RelativeAltitude": "+150.0",
                                "GimbalPitchDegree": "-90", "GimbalYawDegree": "0"},
              "field_of_view_deg": flat.hfov_deg}
    pose = pose_from_vendor(vendor, 640, 512, dem=dem)
    assert pose.height_m == pytest.approx(100.0)  # 200 m altitude over terrain at 100 m, not the take-off's 150
    fp = footprint(pose, dem=dem)
    for (e, n), corner in zip(fp.corners_en, [(0, 0), (640, 0), (640, 512), (0, 512)], strict=True):
        col, row = ground_to_pixel(fp, e, n)  # the terrain point at that corner is on the corner's ray
        assert (col, row) == (pytest.approx(corner[0], abs=1e-3), pytest.approx(corner[1], abs=1e-3))
    # the east edge is higher, so nearer the camera: narrower than the west edge
    tl, tr = fp.corners_en[0], fp.corners_en[1]
    assert tr[0] - ce < ce - tl[0]
    flat_fp = footprint(pose)
    assert flat_fp.corners_en[0][0] == pytest.approx(tl[0], abs=60) and flat_fp.corners_en[1][0] > tr[0] + 1
    with pytest.raises(PoseMissing, match="absolute altitude"):
        pose_from_vendor({**vendor, "xmp_drone_dji": {k: v for k, v in vendor["xmp_drone_dji"].items()
                                                      if k != "AbsoluteAltitude"}}, 640, 512, dem=dem)
    small, _ = _plane_dem(flat, slope=0.0, half=10.0)
    from thermcap.recorder.maps.terrain import DemError

    with pytest.raises(DemError, match="leaves the DEM"):
        footprint(pose_from_vendor(vendor, 640, 512, dem=small), dem=small)


def test_a_footprint_on_a_neighbouring_zones_grid_is_the_same_ground():
    pose = _pose(lat=33.07, lon=-114.0002, yaw=30.0)  # zone 11, 20 m from zone 12
    own, other = footprint(pose), footprint(pose, epsg=32612)
    assert (own.epsg, other.epsg) == (32611, 32612)
    for a, b in zip(own.corners_lonlat, other.corners_lonlat, strict=True):
        assert a == (pytest.approx(b[0], abs=1e-8), pytest.approx(b[1], abs=1e-8))
    assert other.width_m == pytest.approx(own.width_m, rel=1e-3)
