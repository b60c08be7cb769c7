"""Where an image lands on the ground, in the local UTM zone (or one zone given for a whole flight).

Each corner's ray leaves the camera through the lens (the field of view), is turned by the
gimbal's roll, pitch and yaw, and meets the ground: the plane ``height_m`` below the camera, or,
given a DEM (``recorder.maps.terrain``), the terrain itself, where each corner lands at its own
height. A footprint in another zone than its own (a flight that crosses a zone boundary is
mosaicked on one grid) is the same computation with that zone's grid convergence. A corner ray
within ``HORIZON_MARGIN_DEG`` of the horizon (or above it) has no meaningful ground point, so
such an image is refused with the reason instead of stretched to infinity. Near nadir the four
corners are an affine map (a GeoTIFF geotransform); otherwise they are four GCPs. The
uncertainty is the spread of the footprint's centre when each pose input moves by its typical
error (GPS 2 m, height 1 m, gimbal angles 1 deg), added in quadrature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.maps.pose import CameraPose, PoseMissing
from thermcap.recorder.maps.terrain import Dem

__all__ = ["HORIZON_MARGIN_DEG", "NADIR_TOLERANCE_DEG", "Footprint", "FootprintRefused", "footprint",
           "ground_to_pixel", "pixel_to_ground", "utm_epsg"]

HORIZON_MARGIN_DEG = 5.0
NADIR_TOLERANCE_DEG = 5.0
POSE_ERRORS = {"gps_m": 2.0, "height_m": 1.0, "angle_deg": 1.0}


class FootprintRefused(ValueError):
    """The pose puts part of the image at or above the horizon."""


def utm_epsg(lat: float, lon: float) -> int:
    zone = int((lon + 180) // 6) % 60 + 1
    return (32600 if lat >= 0 else 32700) + zone


@dataclass(frozen=True)
class Footprint:
    epsg: int
    corners_en: list[tuple[float, float]]  # TL, TR, BR, BL: (easting, northing) in metres
    corners_lonlat: list[tuple[float, float]]
    camera_en: tuple[float, float]
    nadir: bool
    gsd_m: float  # ground sample distance under the image centre
    uncertainty_m: float
    pose: CameraPose
    notes: list[str] = field(default_factory=list)
    dem: Dem | None = field(default=None, compare=False, repr=False)

    @property
    def width_m(self) -> float:
        (x0, y0), (x1, y1) = self.corners_en[0], self.corners_en[1]
        return math.hypot(x1 - x0, y1 - y0)

    def geotransform(self) -> tuple[float, float, float, float, float, float]:
        """GDAL's (E0, dE/dcol, dE/drow, N0, dN/dcol, dN/drow) from the TL, TR and BL corners."""
        (e0, n0), (e1, n1), _, (e3, n3) = self.corners_en
        w, h = self.pose.width, self.pose.height
        return e0, (e1 - e0) / w, (e3 - e0) / h, n0, (n1 - n0) / w, (n3 - n0) / h

    def to_properties(self) -> dict[str, Any]:
        p = self.pose
        return {"epsg": self.epsg, "nadir": self.nadir, "gsd_m": round(self.gsd_m, 4),
                "uncertainty_m": round(self.uncertainty_m, 2), "width_m": round(self.width_m, 2),
                "height_above_ground_m": p.height_m, "gimbal_pitch_deg": p.pitch_deg, "gimbal_yaw_deg": p.yaw_deg,
                "gimbal_roll_deg": p.roll_deg, "hfov_deg": round(p.hfov_deg, 3), "fov_source": p.fov_source,
                "latitude": p.latitude, "longitude": p.longitude, "absolute_altitude_m": p.absolute_altitude_m,
                "ground": self.dem.describe() if self.dem is not None else "flat plane", "notes": self.notes}


def _basis(pose: CameraPose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera forward, right and up vectors in local East-North-Up."""
    p, y, r = (math.radians(v) for v in (pose.pitch_deg, pose.yaw_deg, pose.roll_deg))
    f = np.array([0.0, math.cos(p), math.sin(p)])
    u = np.array([0.0, -math.sin(p), math.cos(p)])
    right = np.array([1.0, 0.0, 0.0])
    right, u = right * math.cos(r) - u * math.sin(r), u * math.cos(r) + right * math.sin(r)

    def yawed(v: np.ndarray) -> np.ndarray:  # clockwise from north, about up
        return np.array([v[0] * math.cos(y) + v[1] * math.sin(y), -v[0] * math.sin(y) + v[1] * math.cos(y), v[2]])

    return yawed(f), yawed(right), yawed(u)


def _rays(pose: CameraPose, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    f, r, u = _basis(pose)
    tx, ty = math.tan(math.radians(pose.hfov_deg) / 2), math.tan(math.radians(pose.vfov_deg) / 2)
    return f[None, :] + sx[:, None] * tx * r[None, :] - sy[:, None] * ty * u[None, :]


@dataclass(frozen=True)
class _Ground:
    """The terrain a footprint's rays meet: the DEM and the camera on the map grid."""

    dem: Dem
    epsg: int
    camera_en: tuple[float, float]
    gamma: float  # grid convergence, radians
    altitude_m: float

    @classmethod
    def of(cls, pose: CameraPose, dem: Dem | None, epsg: int) -> _Ground | None:
        if dem is None:
            return None
        if pose.absolute_altitude_m is None:
            raise PoseMissing("a DEM needs the camera's absolute altitude (AbsoluteAltitude or a GPS altitude)")
        ce, cn, gamma = _grid(pose, epsg)
        return cls(dem, epsg, (ce, cn), gamma, pose.absolute_altitude_m)

    def offsets(self, d: np.ndarray) -> np.ndarray:
        """ENU ground offsets of ENU ray directions ``d`` (k, 3)."""
        cg, sg = math.cos(self.gamma), math.sin(self.gamma)
        grid = np.stack([d[:, 0] * cg + d[:, 1] * sg, -d[:, 0] * sg + d[:, 1] * cg, d[:, 2]], axis=1)
        hit = self.dem.intersect(self.altitude_m, self.camera_en, grid, self.epsg)
        de, dn = hit[:, 0] - self.camera_en[0], hit[:, 1] - self.camera_en[1]
        return np.stack([de * cg - dn * sg, de * sg + dn * cg], axis=1)


def _ground_offsets(pose: CameraPose, sx: np.ndarray, sy: np.ndarray, ground: _Ground | None = None) -> np.ndarray:
    d = _rays(pose, sx, sy)
    elevation = np.degrees(np.arcsin(d[:, 2] / np.linalg.norm(d, axis=1)))
    if np.any(elevation > -HORIZON_MARGIN_DEG):
        worst = float(elevation.max())
        raise FootprintRefused(
            f"gimbal pitch {pose.pitch_deg:g} deg: part of the image looks {abs(worst):.1f} deg "
            f"{'above' if worst > 0 else 'below'} the horizon (within {HORIZON_MARGIN_DEG:g} deg of it or above), "
            f"so it has no ground footprint")
    if ground is not None:
        return ground.offsets(d)
    t = -pose.height_m / d[:, 2]
    return d[:, :2] * t[:, None]


_CORNERS = (np.array([-1.0, 1.0, 1.0, -1.0]), np.array([-1.0, -1.0, 1.0, 1.0]))  # TL, TR, BR, BL


def _centre_offset(pose: CameraPose, ground: _Ground | None) -> np.ndarray:
    return _ground_offsets(pose, np.array([0.0]), np.array([0.0]), ground)[0]


def _grid(pose: CameraPose, epsg: int) -> tuple[float, float, float]:
    """The camera's UTM position and the grid convergence (true north from grid north, radians):
    away from the central meridian UTM grid north is not true north, so ENU offsets are turned
    by it and a north-facing footprint is north on the map."""
    from pyproj import Transformer

    to_utm = Transformer.from_crs(4326, epsg, always_xy=True)
    ce, cn = to_utm.transform(pose.longitude, pose.latitude)
    e_n, n_n = to_utm.transform(pose.longitude, pose.latitude + 1e-4)
    return ce, cn, math.atan2(e_n - ce, n_n - cn)


def pixel_to_ground(fp: Footprint, cols: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UTM easting and northing of image points (pixel coordinates: 0..width, 0..height)."""
    pose = fp.pose
    sx = np.asarray(cols, dtype=np.float64) / pose.width * 2 - 1
    sy = np.asarray(rows, dtype=np.float64) / pose.height * 2 - 1
    off = _ground_offsets(pose, sx.ravel(), sy.ravel(), _Ground.of(pose, fp.dem, fp.epsg))
    ce, cn, gamma = _grid(pose, fp.epsg)
    cg, sg = math.cos(gamma), math.sin(gamma)
    e = ce + off[:, 0] * cg + off[:, 1] * sg
    n = cn - off[:, 0] * sg + off[:, 1] * cg
    return e.reshape(np.shape(cols)), n.reshape(np.shape(cols))


def _moved(pose: CameraPose, name: str, delta: float) -> CameraPose:
    if name == "height_m" and pose.absolute_altitude_m is not None:  # over a DEM the altitude is what moves
        return replace(pose, height_m=pose.height_m + delta, absolute_altitude_m=pose.absolute_altitude_m + delta)
    return replace(pose, **{name: getattr(pose, name) + delta})


def footprint(pose: CameraPose, *, epsg: int | None = None, dem: Dem | None = None) -> Footprint:
    """The image's footprint on the grid of ``epsg`` (default: its own UTM zone), on a flat
    ground plane or on ``dem``'s terrain. A DEM that does not cover the view is a DemError."""
    from pyproj import Transformer

    epsg = epsg or utm_epsg(pose.latitude, pose.longitude)
    ground = _Ground.of(pose, dem, epsg)
    offsets = _ground_offsets(pose, *_CORNERS, ground)
    to_ll = Transformer.from_crs(epsg, 4326, always_xy=True)
    ce, cn, gamma = _grid(pose, epsg)
    cg, sg = math.cos(gamma), math.sin(gamma)
    grid = [(ce + x * cg + y * sg, cn - x * sg + y * cg) for x, y in offsets]
    lonlat = [to_ll.transform(e, n) for e, n in grid]
    centre_px = _ground_offsets(pose, np.array([0.0, 2.0 / pose.width]), np.array([0.0, 0.0]), ground)
    gsd = float(np.linalg.norm(centre_px[1] - centre_px[0]))
    base = _centre_offset(pose, ground)
    spread = [POSE_ERRORS["gps_m"] ** 2]
    for name, delta in (("height_m", POSE_ERRORS["height_m"]), ("pitch_deg", POSE_ERRORS["angle_deg"]),
                        ("yaw_deg", POSE_ERRORS["angle_deg"]), ("roll_deg", POSE_ERRORS["angle_deg"])):
        try:
            moved_pose = _moved(pose, name, delta)
            moved = _centre_offset(moved_pose, _Ground.of(moved_pose, dem, epsg))
        except FootprintRefused:
            moved = base + 10 * pose.height_m  # so near the horizon that an error of one step is unbounded
        spread.append(float(np.sum((moved - base) ** 2)))
    nadir = abs(pose.pitch_deg + 90) <= NADIR_TOLERANCE_DEG and abs(pose.roll_deg) <= NADIR_TOLERANCE_DEG
    notes = [] if nadir else ["oblique: the corners are GCPs, the footprint is a trapezoid"]
    if dem is not None:
        notes.append(f"on the terrain of {Path(dem.source).name}: each corner at its own height")
    if epsg != utm_epsg(pose.latitude, pose.longitude):
        notes.append(f"on the grid of EPSG:{epsg}, not the image's own UTM zone")
    return Footprint(epsg, grid, [(float(a), float(b)) for a, b in lonlat], (ce, cn), nadir, gsd,
                     math.sqrt(sum(spread)), pose, notes, dem)


def ground_to_pixel(fp: Footprint, easting: float, northing: float) -> tuple[float, float] | None:
    """Where a ground point appears in the image (column, row), or None if outside the view."""
    pose = fp.pose
    f, r, u = _basis(pose)
    ce, cn, gamma = _grid(pose, fp.epsg)
    de, dn = easting - ce, northing - cn
    x, y = de * math.cos(gamma) - dn * math.sin(gamma), de * math.sin(gamma) + dn * math.cos(gamma)
    if fp.dem is not None and pose.absolute_altitude_m is not None:
        z = float(fp.dem.elevation(np.array([easting]), np.array([northing]), fp.epsg)[0]) - pose.absolute_altitude_m
        if not math.isfinite(z):
            return None
    else:
        z = -pose.height_m
    d = np.array([x, y, z])
    depth = float(d @ f)
    if depth <= 0:
        return None
    tx, ty = math.tan(math.radians(pose.hfov_deg) / 2), math.tan(math.radians(pose.vfov_deg) / 2)
    sx, sy = float(d @ r) / depth / tx, -float(d @ u) / depth / ty
    if abs(sx) > 1 + 1e-6 or abs(sy) > 1 + 1e-6:  # the image edge itself is in view
        return None
    return (sx + 1) / 2 * pose.width, (sy + 1) / 2 * pose.height
