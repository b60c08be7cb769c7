"""Footprints on a flat ground plane from a camera's pose: the geometry checked against what it
must be (2·h·tan(FOV/2) at nadir, the yaw's direction on the map, corners that project back to
the image's corners), honest refusals near the horizon, uncertainty that grows when oblique."""

from __future__ import annotations

import math

import pytest

from recorder.maps.footprint import FootprintRefused, footprint, ground_to_pixel, utm_epsg
from recorder.maps.pose import CameraPose, PoseMissing, pose_from_vendor

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
