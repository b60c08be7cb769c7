"""A camera's pose at one frame, from the metadata an importer kept.

DJI's XMP ``drone-dji`` fields give the position (GPS), the height above the take-off point
(``RelativeAltitude``) and the gimbal's pitch, yaw and roll. FLIR drone cameras (Vue Pro R, Duo
Pro R) write the camera's attitude in Pix4D's XMP ``Camera`` namespace (``Camera:Yaw``,
``Camera:Pitch``, ``Camera:Roll``, rationals such as ``3250/100``; Pix4D's convention: pitch 0 is
nadir, so DJI's pitch is ``Camera:Pitch - 90``) and the height above take-off in FLIR's own
``FLIR:MAVRelativeAltitude``; the position comes from FLIR's GPSInfo record or EXIF GPS. A FLIR
file with a position and no attitude (a handheld camera, a Duo Pro R FFF) gets no footprint,
and says so. The field of view is, in order: FLIR CameraInfo's ``FieldOfView`` (the calibrated
thermal lens), EXIF's 35 mm equivalent focal length (``2·atan(18 / f35)`` horizontally,
exiftool's convention), or a per-model table with its source.

Over a DEM the camera's absolute altitude (``AbsoluteAltitude``, or the GPS altitude) minus the
terrain under it is the height; without one, the take-off point's height, or a ground elevation
the user gives, defines a flat ground plane.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from thermcap.recorder.maps.terrain import Dem

__all__ = ["LENS_TABLE", "CameraPose", "PoseMissing", "pose_from_vendor"]


class PoseMissing(ValueError):
    """The file does not say enough to place the image (the message says what is missing)."""


#: horizontal field of view (degrees) of thermal cameras whose files carry neither a 35 mm
#: equivalent focal length nor FLIR's FieldOfView, by (EXIF model, image width, focal length mm);
#: a model of "=NAME" must equal the EXIF model, otherwise contain it; None matches any value.
#: Sources: the makers' datasheets.
LENS_TABLE: dict[tuple[str, int | None, float | None], tuple[float, str]] = {
    ("XT2", 640, 9.0): (69.0, "FLIR Zenmuse XT2 datasheet: 640, 9 mm lens, 69 x 56 deg"),
    ("XT2", 640, 13.0): (45.0, "FLIR Zenmuse XT2 datasheet: 640, 13 mm lens, 45 x 37 deg"),
    ("XT2", 640, 19.0): (32.0, "FLIR Zenmuse XT2 datasheet: 640, 19 mm lens, 32 x 26 deg"),
    ("XT2", 640, 25.0): (25.0, "FLIR Zenmuse XT2 datasheet: 640, 25 mm lens, 25 x 20 deg"),
    # a Zenmuse XT/XT2 writes EXIF Make "DJI", Model "FLIR" (the shared samples' DJI_XT2.jpg)
    ("=FLIR", 640, 9.0): (69.0, "FLIR Zenmuse XT2 datasheet (EXIF Model FLIR): 640, 9 mm lens, 69 x 56 deg"),
    ("=FLIR", 640, 13.0): (45.0, "FLIR Zenmuse XT2 datasheet (EXIF Model FLIR): 640, 13 mm lens, 45 x 37 deg"),
    ("=FLIR", 640, 19.0): (32.0, "FLIR Zenmuse XT2 datasheet (EXIF Model FLIR): 640, 19 mm lens, 32 x 26 deg"),
    ("=FLIR", 640, 25.0): (25.0, "FLIR Zenmuse XT2 datasheet (EXIF Model FLIR): 640, 25 mm lens, 25 x 20 deg"),
    ("MAVIC2-ENTERPRISE-ADVANCED", None, None): (45.9, "DJI Mavic 2 Enterprise Advanced datasheet: thermal DFOV "
                                                      "57 deg"),
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
    """A number as XMP writes one: "+16.508", or a rational "3250/100" (FLIR)."""
    text = str(v).strip() if v is not None else ""
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            x = float(num) / float(den)
        else:
            x = float(text)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return x if math.isfinite(x) else None


def _hfov(vendor: dict[str, Any], model: str, width: int) -> tuple[float, str]:
    fov = _num(vendor.get("field_of_view_deg"))
    if fov and 0 < fov < 180:
        return fov, f"FLIR CameraInfo FieldOfView {fov:g} deg"
    f35 = _num(vendor.get("exif_focal_length_35mm"))
    if f35 and f35 > 0:
        return math.degrees(2 * math.atan(18.0 / f35)), f"EXIF FocalLengthIn35mmFormat {f35:g} mm"
    focal = _num(vendor.get("exif_focal_length_mm"))
    for (name, cols, lens), (fov, source) in LENS_TABLE.items():
        named = model.upper() == name[1:].upper() if name.startswith("=") else name.upper() in model.upper()
        if named and (cols is None or cols == width) and \
                (lens is None or (focal is not None and abs(focal - lens) < 0.5)):
            return fov, source
    raise PoseMissing(f"no field of view: no 35 mm equivalent focal length in EXIF and {model or 'this camera'} "
                      f"(focal length {focal or '?'} mm) is not in the lens table")


def _attitude(vendor: dict[str, Any]) -> tuple[float, float, float] | None:
    """(pitch, yaw, roll) in DJI's convention (pitch -90 looks straight down)."""
    xmp = vendor.get("xmp_drone_dji") or {}
    pitch, yaw = _num(xmp.get("GimbalPitchDegree")), _num(xmp.get("GimbalYawDegree"))
    if pitch is not None and yaw is not None:
        return pitch, yaw, _num(xmp.get("GimbalRollDegree")) or 0.0
    cam = vendor.get("xmp_camera") or {}
    pitch, yaw = _num(cam.get("Pitch")), _num(cam.get("Yaw"))
    if pitch is not None and yaw is not None:
        return pitch - 90.0, yaw, _num(cam.get("Roll")) or 0.0
    return None


def pose_from_vendor(vendor: dict[str, Any], width: int, height: int, *,
                     ground_elevation_m: float | None = None, dem: Dem | None = None) -> CameraPose:
    """The pose of one imported frame; PoseMissing says what the file lacks."""
    xmp = vendor.get("xmp_drone_dji") or {}
    lat, lon = _num(xmp.get("GpsLatitude")), _num(xmp.get("GpsLongitude") or xmp.get("GpsLongtitude"))
    gps = vendor.get("gps") or {}
    if lat is None or lon is None:
        lat, lon = _num(gps.get("latitude")), _num(gps.get("longitude"))
    if lat is None or lon is None:
        raise PoseMissing("no position (no drone-dji GPS, FLIR GPSInfo or EXIF GPS)")
    attitude = _attitude(vendor)
    if attitude is None:
        raise PoseMissing("no camera attitude (no gimbal pitch and yaw in the file's XMP: neither drone-dji "
                          "Gimbal*Degree nor Pix4D Camera:Pitch/Yaw)")
    pitch, yaw, roll = attitude
    absolute = _num(xmp.get("AbsoluteAltitude"))
    if absolute is None:
        absolute = _num(gps.get("altitude_m"))
    relative = _num(xmp.get("RelativeAltitude"))
    if relative is None:
        relative = _num((vendor.get("xmp_flir") or {}).get("MAVRelativeAltitude"))
    h: float | None
    if dem is not None:
        if absolute is None:
            raise PoseMissing("a DEM needs the camera's absolute altitude (no AbsoluteAltitude, no GPS altitude)")
        ground = dem.elevation_at_lonlat(lon, lat)
        if not math.isfinite(ground):
            raise PoseMissing(f"the camera ({lat:.6f}, {lon:.6f}) is outside the DEM {dem.source}")
        h = absolute - ground
    elif ground_elevation_m is not None and absolute is not None:
        h = absolute - ground_elevation_m
    else:
        h = relative
    if h is None:
        raise PoseMissing("no height above the ground (no RelativeAltitude or FLIR MAVRelativeAltitude, and no "
                          "ground elevation or DEM given)")
    if h <= 0:
        raise PoseMissing(f"the camera is {h:g} m above the ground plane: on or below it")
    model = str(vendor.get("exif_model") or "")
    hfov, source = _hfov(vendor, model, width)
    return CameraPose(lat, lon, h, pitch, yaw, roll, hfov, width, height, source, absolute)
