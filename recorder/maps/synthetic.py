"""A simulated flight: a camera at known poses over a flat scene with warm targets at known UTM
positions, rendered through the same footprint geometry the maps use, and recorded like an
imported drone survey (DJI ``drone-dji`` pose fields on ``/import/source``). The proof that a
mosaic, a footprint or a hot spot lands where it should."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, SensorInfo
from thermcap.recorder.maps.footprint import footprint, pixel_to_ground
from thermcap.recorder.maps.pose import CameraPose
from thermcap.recorder.maps.terrain import Dem
from thermcap.recorder.radiometry import LinearModel

__all__ = ["FlightSource", "GroundTarget", "lawnmower"]


@dataclass(frozen=True)
class GroundTarget:
    easting: float
    northing: float
    radius_m: float
    temp_c: float


@dataclass
class FlightSource(FrameSource):
    """Frames of ``poses`` over a scene at ``background_c`` with ``targets`` (UTM ``epsg``)."""

    poses: list[CameraPose]
    targets: list[GroundTarget]
    epsg: int
    background_c: float = 18.0
    start_time_ns: int = 1_800_000_000_000_000_000
    f35_mm: float = 58.0
    reported: list[CameraPose] | None = None  # what the metadata says (a noisy GPS), if not the truth
    dem: Dem | None = None  # the terrain the scene lies on (poses then carry their absolute altitude)
    takeoff_elevation_m: float | None = None  # over a DEM: RelativeAltitude is above this
    name: str = "flight"
    extra_topics: ClassVar[dict[str, dict[str, Any]]] = {"/import/source": {"title": "thermcap.ImportSource"}}
    can_wait: bool = True
    model: Any = field(default_factory=lambda: LinearModel())

    def __post_init__(self) -> None:
        p = self.poses[0]
        self.sensor = SensorInfo(model="simulated drone thermal camera", sensor_id="SIMFLIGHT", width=p.width,
                                 height=p.height, frame_rate_hz=1.0, type="simulated")

    def render(self, pose: CameraPose) -> np.ndarray:
        fp = footprint(pose, epsg=self.epsg, dem=self.dem)  # the targets' grid, even across a zone boundary
        cols, rows = np.meshgrid(np.arange(pose.width) + 0.5, np.arange(pose.height) + 0.5)
        e, n = pixel_to_ground(fp, cols, rows)
        temps = np.full(e.shape, self.background_c)
        for t in self.targets:
            temps = np.where((e - t.easting) ** 2 + (n - t.northing) ** 2 <= t.radius_m ** 2, t.temp_c, temps)
        m = self.model
        return np.clip(np.round((temps - m.offset_c) / m.scale_c_per_count), 0, 2 ** m.bit_depth - 1).astype(np.uint16)

    def frames(self) -> Iterator[CapturedFrame]:
        for i, pose in enumerate(self.poses):
            said = (self.reported or self.poses)[i]
            xmp = {"GpsLatitude": f"{said.latitude:.9f}", "GpsLongitude": f"{said.longitude:.9f}",
                   "RelativeAltitude": f"{said.height_m:+.3f}", "GimbalPitchDegree": f"{said.pitch_deg:+.2f}",
                   "GimbalYawDegree": f"{said.yaw_deg:+.2f}", "GimbalRollDegree": f"{said.roll_deg:+.2f}"}
            if said.absolute_altitude_m is not None:
                xmp["AbsoluteAltitude"] = f"{said.absolute_altitude_m:+.3f}"
                if self.takeoff_elevation_m is not None:
                    xmp["RelativeAltitude"] = f"{said.absolute_altitude_m - self.takeoff_elevation_m:+.3f}"
            vendor = {"xmp_drone_dji": xmp, "exif_focal_length_35mm": self.f35_mm, "exif_model": "SIMFLIGHT"}
            yield CapturedFrame(index=i, timestamp_ns=self.start_time_ns + i * 1_000_000_000,
                                pixels=self.render(pose),
                                messages=[("/import/source", {"path": f"flight_{i:04d}", "format": "simulated",
                                                              "layout": None, "vendor": vendor})])
            if self.stopped:
                return


def lawnmower(lat: float, lon: float, *, height_m: float, legs: int, per_leg: int, spacing_m: float,
              hfov_deg: float, width: int = 320, height: int = 256, pitch_deg: float = -90.0) -> list[CameraPose]:
    """Poses along north-south legs ``spacing_m`` apart, images ``spacing_m`` apart on each leg."""
    poses = []
    m_per_deg_lat = 111_320.0
    m_per_deg_lon = 111_320.0 * math.cos(math.radians(lat))
    for leg in range(legs):
        for k in range(per_leg):
            north = (k if leg % 2 == 0 else per_leg - 1 - k) * spacing_m
            east = leg * spacing_m
            poses.append(CameraPose(lat + north / m_per_deg_lat, lon + east / m_per_deg_lon, height_m, pitch_deg,
                                    0.0 if leg % 2 == 0 else 180.0, 0.0, hfov_deg, width, height, "synthetic"))
    return poses
