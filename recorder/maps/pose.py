"""A camera's pose at one frame, from the metadata an importer kept.

DJI's XMP ``drone-dji`` fields give the position (GPS), the height above the take-off point
(``RelativeAltitude``) and the gimbal's pitch, yaw and roll; FLIR's GPSInfo or EXIF GPS give a
position only (no attitude, so no footprint). The field of view comes from EXIF's 35 mm
equivalent focal length (``2·atan(18 / f35)`` horizontally, exiftool's convention) or, where a
file lacks it, a per-model table with its source.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["LENS_TABLE", "CameraPose", "PoseMissing", "pose_from_vendor"]


class PoseMissing(ValueError):
    """The file does not say enough to place the image (the message says what is missing)."""


#: horizontal field of view (degrees) of thermal cameras whose files do not carry a usable focal
#: length, by (model, focal length mm); sources: the makers' datasheets
LENS_TABLE: dict[tuple[str, float | None], tuple[float, str]] = {
    ("XT2", 9.0): (69.0, "FLIR Zenmuse XT2 datasheet: 9 mm lens, 69 x 56 deg"),
    ("XT2", 13.0): (45.0, "FLIR Zenmuse XT2 datasheet: 13 mm lens, 45 x 37 deg"),
    ("XT2", 19.0): (32.0, "FLIR Zenmuse XT2 datasheet: 19 mm lens, 32 x 26 deg"),
    ("XT2", 25.0): (25.0, "FLIR Zenmuse XT2 datasheet: 25 mm lens, 25 x 20 deg"),
    ("MAVIC2-ENTERPRISE-ADVANCED", None): (45.9, "DJI Mavic 2 Enterprise Advanced datasheet: thermal DFOV 57 deg"),
}


@dataclass(frozen=True)
class CameraPose:
    latitude: float
    longitude: float
    height_m: float  # above the ground plane (the take-off point, unless a ground elevation is given)
    pitch_deg: float  # -90: looking straight down
    yaw_deg: float  # clockwise from north
    roll_deg: float
    hfov_deg: float
    width: int
    height: int
    fov_source: str
    absolute_altitude_m: float | None = None

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2 * math.atan(math.tan(math.radians(self.hfov_deg) / 2) * self.height / self.width))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _num(v: Any) -> float | None:
    try:
        x = float(str(v).strip())
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _hfov(vendor: dict[str, Any], model: str) -> tuple[float, str]:
    f35 = _num(vendor.get("exif_focal_length_35mm"))
    if f35 and f35 > 0:
        return math.degrees(2 * math.atan(18.0 / f35)), f"EXIF FocalLengthIn35mmFormat {f35:g} mm"
    focal = _num(vendor.get("exif_focal_length_mm"))
    for (name, lens), (fov, source) in LENS_TABLE.items():
        if name.upper() in model.upper() and (lens is None or (focal is not None and abs(focal - lens) < 0.5)):
            return fov, source
    raise PoseMissing(f"no field of view: no 35 mm equivalent focal length in EXIF and {model or 'this camera'} "
                      f"(focal length {focal or '?'} mm) is not in the lens table")


def pose_from_vendor(vendor: dict[str, Any], width: int, height: int, *,
                     ground_elevation_m: float | None = None) -> CameraPose:
    """The pose of one imported frame; PoseMissing says what the file lacks."""
    xmp = vendor.get("xmp_drone_dji") or {}
    lat, lon = _num(xmp.get("GpsLatitude")), _num(xmp.get("GpsLongitude") or xmp.get("GpsLongtitude"))
    gps = vendor.get("gps") or {}
    if lat is None or lon is None:
        lat, lon = _num(gps.get("latitude")), _num(gps.get("longitude"))
    if lat is None or lon is None:
        raise PoseMissing("no position (no drone-dji GPS, FLIR GPSInfo or EXIF GPS)")
    pitch, yaw = _num(xmp.get("GimbalPitchDegree")), _num(xmp.get("GimbalYawDegree"))
    roll = _num(xmp.get("GimbalRollDegree")) or 0.0
    if pitch is None or yaw is None:
        raise PoseMissing("no camera attitude (no gimbal pitch and yaw in the file's XMP)")
    absolute = _num(xmp.get("AbsoluteAltitude"))
    h: float | None
    if ground_elevation_m is not None and absolute is not None:
        h = absolute - ground_elevation_m
    else:
        h = _num(xmp.get("RelativeAltitude"))
    if h is None:
        raise PoseMissing("no height above the ground (no RelativeAltitude, and no ground elevation given)")
    if h <= 0:
        raise PoseMissing(f"the camera is {h:g} m above the ground plane: on or below it")
    model = str(vendor.get("exif_model") or "")
    hfov, source = _hfov(vendor, model)
    return CameraPose(lat, lon, h, pitch, yaw, roll, hfov, width, height, source, absolute)
