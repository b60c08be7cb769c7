"""TERRA-REF gantry images on the map, placed as the TERRA-REF pipeline places them.

terrautils' ``spatial.calculate_gps_bounds`` for ``flirIrCamera`` (terraref/terrautils, 1.5.5):
the camera is at the gantry position plus its location in the camera box; its field of view
(given at 2 m) scales with the camera's height above the canopy, the camera's height plus the
sensor's ``rail_height_offset``; the bounds' corners go from scanalyzer coordinates (x north,
y west) to UTM zone 12N by the published linear transform (``scanalyzer_to_utm``), then to
latitude and longitude, with the pipeline's fixed shift. The pipeline rotates the raw 480x640
image with ``numpy.rot90(raw, 3)`` before writing (extractors-multispectral ``flir2tif``), and
writes EPSG:4326 north-up. The sensor's fixed values that the raw LemnaTec JSON lacks come from
terraref/sensor-metadata (``sensors/flirIrCamera``).

One placement for every CRS: the pipeline publishes only those shifted latitude/longitude
bounds, and where terrautils speaks UTM it projects the same bounds (``tuples_to_utm``), so the
UTM 12N product is the published ground box projected, not the unshifted linear transform (which
sits the fixed shift, about 2.5 m, away). Both products name this rule (``PLACEMENT``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["FLIR_FIXED", "PLACEMENT", "GantryFootprint", "gantry_footprint", "scanalyzer_to_utm"]

UTM_12N = 32612
# terrautils spatial.scanalyzer_to_utm: Mx = ax + bx*Gx + cx*Gy, My = ay + by*Gx + cy*Gy
_AX, _BX, _CX = 409012.2032, 0.009, -0.9986
_AY, _BY, _CY = 3659974.971, 1.0002, 0.0078
# terrautils spatial._get_bounding_box_with_formula's fixed shift of the lat/lon bounds
_LAT_SHIFT, _LON_SHIFT = 0.000015258894, 0.000020308287
PLACEMENT = ("terrautils calculate_gps_bounds (flirIrCamera): gantry position + camera box, field of view scaled "
             "to the height above the canopy, scanalyzer->UTM 12N linear transform of the NW and SE corners, to "
             f"latitude/longitude, then the pipeline's fixed shift (latitude -{_LAT_SHIFT} deg, longitude "
             f"+{_LON_SHIFT} deg); north-up in EPSG:4326 as published; in UTM 12N the same published bounds "
             "projected (terrautils tuples_to_utm), so both CRSs place the image on the same ground")

#: terraref/sensor-metadata sensors/flirIrCamera/sensor_fixed_metadata.json (2018-08-30), by start date
FLIR_FIXED: list[dict[str, Any]] = [
    {"start_date": "2018-08-18", "camera_box_m": (0.346, 2.250, 0.520), "fov_at_2m_m": (1.496, 1.105),
     "rail_height_offset_m": 1.0},
    {"start_date": "2012-01-01", "camera_box_m": (0.877, 1.361, 0.520), "fov_at_2m_m": (1.496, 1.105),
     "rail_height_offset_m": 1.0},
]


def scanalyzer_to_utm(gx: float, gy: float) -> tuple[float, float]:
    return _AX + _BX * gx + _CX * gy, _AY + _BY * gx + _CY * gy


@dataclass(frozen=True)
class GantryFootprint:
    lat_min: float
    lat_max: float
    lon_min: float
    lon_max: float
    corners_utm: list[tuple[float, float]]  # NW, NE, SE, SW by the linear transform alone (before the shift)
    fov_m: tuple[float, float]  # on the canopy: along x (north), along y (west)
    height_above_canopy_m: float
    source: str

    def geotransform_4326(self, width: int, height: int) -> tuple[float, ...]:
        """As the pipeline writes it: north-up, from the bounds."""
        return (self.lon_min, (self.lon_max - self.lon_min) / width, 0.0, self.lat_max, 0.0,
                -(self.lat_max - self.lat_min) / height)

    def published_corners_utm(self) -> list[tuple[float, float]]:
        """NW, NE, SE, SW of the published (shifted) bounds in UTM 12N."""
        from pyproj import Transformer

        to_utm = Transformer.from_crs(4326, UTM_12N, always_xy=True)
        return [to_utm.transform(lon, lat) for lon, lat in
                ((self.lon_min, self.lat_max), (self.lon_max, self.lat_max), (self.lon_max, self.lat_min),
                 (self.lon_min, self.lat_min))]

    def geotransform_utm(self, width: int, height: int) -> tuple[float, ...]:
        """The published ground box in UTM 12N: an affine through its NW, NE and SW corners (the
        box, a rectangle in latitude/longitude, is a parallelogram in UTM to well under a mm)."""
        (e0, n0), (e1, n1), _, (e3, n3) = self.published_corners_utm()
        return e0, (e1 - e0) / width, (e3 - e0) / height, n0, (n1 - n0) / width, (n3 - n0) / height

    def shift_m(self) -> tuple[float, float]:
        """How far the pipeline's fixed shift moves the image on the ground: (east, north) metres."""
        (e_pub, n_pub), (e_lin, n_lin) = self.published_corners_utm()[0], self.corners_utm[0]
        return e_pub - e_lin, n_pub - n_lin

    def to_properties(self) -> dict[str, Any]:
        east, north = self.shift_m()
        return {"crs_published": "EPSG:4326", "bounds": [self.lat_min, self.lat_max, self.lon_min, self.lon_max],
                "fov_on_canopy_m": list(self.fov_m), "height_above_canopy_m": round(self.height_above_canopy_m, 4),
                "placement": PLACEMENT, "pipeline_shift_m": {"east": round(east, 3), "north": round(north, 3)},
                "source": self.source}


def _num(v: Any) -> float | None:
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _fixed(date_iso: str | None) -> dict[str, Any]:
    for entry in FLIR_FIXED:
        if date_iso is None or date_iso >= entry["start_date"]:
            return entry
    return FLIR_FIXED[-1]


def gantry_footprint(vendor: dict[str, Any], date_iso: str | None) -> GantryFootprint | None:
    """None where the frame has no gantry position (not a TERRA-REF image)."""
    from pyproj import Transformer

    pos = vendor.get("position_m") or {}
    gx, gy, gz = (_num(pos.get(k)) for k in "xyz")
    if gx is None or gy is None or gz is None:
        return None
    fixed = _fixed(date_iso)
    box = vendor.get("camera_box_m") or {}
    cb = [_num(box.get(k)) for k in "xyz"]
    cambox: tuple[float, ...] = tuple(v for v in cb if v is not None) if None not in cb else fixed["camera_box_m"]
    fov = vendor.get("field_of_view_m") or {}
    f2 = [_num(fov.get("x")), _num(fov.get("y"))]
    fov2m: tuple[float, ...] = tuple(v for v in f2 if v is not None) if None not in f2 else fixed["fov_at_2m_m"]
    cx, cy, cz = gx + cambox[0], gy + cambox[1], gz + cambox[2]
    above = cz + fixed["rail_height_offset_m"]
    fx, fy = fov2m[0] * above / 2, fov2m[1] * above / 2
    x_n, x_s, y_w, y_e = cx + fx / 2, cx - fx / 2, cy + fy / 2, cy - fy / 2
    to_ll = Transformer.from_crs(UTM_12N, 4326, always_xy=True)
    corners = [scanalyzer_to_utm(x_n, y_w), scanalyzer_to_utm(x_n, y_e), scanalyzer_to_utm(x_s, y_e),
               scanalyzer_to_utm(x_s, y_w)]  # NW, NE, SE, SW
    nw_lon, nw_lat = to_ll.transform(*corners[0])
    se_lon, se_lat = to_ll.transform(*corners[2])
    return GantryFootprint(lat_min=se_lat - _LAT_SHIFT, lat_max=nw_lat - _LAT_SHIFT, lon_min=nw_lon + _LON_SHIFT,
                           lon_max=se_lon + _LON_SHIFT, corners_utm=corners, fov_m=(fx, fy),
                           height_above_canopy_m=above,
                           source="terrautils calculate_gps_bounds (flirIrCamera); sensor-metadata of "
                                  f"{fixed['start_date']}")
