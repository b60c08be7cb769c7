"""The ground under a flight when it is not flat: a digital elevation model (DEM).

A DEM is any single-band raster GDAL reads (a GeoTIFF from SRTM, Copernicus GLO-30, a lidar
survey), in any CRS, with heights in metres. A camera ray meets it where the ray's height first
drops below the terrain: ``intersect`` brackets that point between the heights the ray has at the
DEM's highest and lowest cells, steps through the bracket and refines the first crossing by
bisection, so a slope or a hill moves each corner of a footprint to where it really lands.

The heights must share the camera altitude's vertical datum. DJI's ``AbsoluteAltitude`` and a
GPS altitude are heights above the geoid (EGM96) on most firmware, as SRTM and Copernicus DEMs
are; an ellipsoidal DEM is tens of metres off from them and moves every footprint.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.install_hint import install_command

__all__ = ["Dem", "DemError"]

#: steps through the bracket before bisection; a crossing narrower than a step may be missed only
#: where the terrain rises and falls again within 1/64 of the ray's bracket
_STEPS = 64
_BISECTIONS = 26  # a bracket of 100 m narrowed to under 2 micrometres


class DemError(ThermcapError):
    """The DEM cannot be read, or a point asked of it lies outside it."""


@dataclass
class Dem:
    heights: np.ndarray  # (rows, cols) float64, NaN where the DEM has no data
    transform: tuple[float, float, float, float, float, float]  # GDAL order: x0, dx/col, dx/row, y0, dy/col, dy/row
    crs_wkt: str
    source: str
    _to_dem: dict[int, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def from_file(cls, path: str | Path) -> Dem:
        try:
            import rasterio
        except ImportError as exc:  # pragma: no cover - the geo extra
            raise DemError(f"a DEM needs rasterio ({install_command('maps')})") from exc
        try:
            with rasterio.open(path) as src:
                band = src.read(1, masked=True).astype(np.float64)
                if src.crs is None:
                    raise DemError(f"{path}: the DEM has no CRS; georeference it first (gdal_edit.py -a_srs)")
                t = src.transform
                dem = cls(band.filled(np.nan), (t.c, t.a, t.b, t.f, t.d, t.e), src.crs.to_wkt(), str(path))
        except rasterio.errors.RasterioError as exc:
            raise DemError(f"{path}: not a readable DEM ({exc})") from None
        if not np.isfinite(dem.heights).any():
            raise DemError(f"{path}: the DEM holds no valid height")
        return dem

    @property
    def zrange(self) -> tuple[float, float]:
        return float(np.nanmin(self.heights)), float(np.nanmax(self.heights))

    def _transformer(self, epsg: int) -> Any:
        """pyproj's transformer from ``epsg`` to the DEM's CRS; None where they are the same."""
        if epsg not in self._to_dem:
            from pyproj import CRS, Transformer

            dem_crs = CRS.from_wkt(self.crs_wkt)
            self._to_dem[epsg] = None if dem_crs.to_epsg() == epsg else \
                Transformer.from_crs(epsg, dem_crs, always_xy=True)
        return self._to_dem[epsg]

    def elevation(self, x: np.ndarray, y: np.ndarray, epsg: int) -> np.ndarray:
        """Terrain height (bilinear between cell centres) at points given in ``epsg``; NaN
        outside the DEM or on its no-data cells."""
        from scipy.ndimage import map_coordinates

        dx, dy = np.asarray(x, np.float64), np.asarray(y, np.float64)
        to_dem = self._transformer(epsg)
        if to_dem is not None:
            dx, dy = to_dem.transform(dx, dy)
        x0, a, b, y0, c, d = self.transform
        det = a * d - b * c
        u, v = np.asarray(dx) - x0, np.asarray(dy) - y0
        col = (d * u - b * v) / det - 0.5  # cell centres sit at half a cell
        row = (-c * u + a * v) / det - 0.5
        shape = np.shape(col)
        out = map_coordinates(self.heights, [np.ravel(row), np.ravel(col)], order=1, mode="constant",
                              cval=np.nan, prefilter=False)
        rows, cols = self.heights.shape
        outside = (np.ravel(row) < -0.5) | (np.ravel(row) > rows - 0.5) | (np.ravel(col) < -0.5) | \
            (np.ravel(col) > cols - 0.5)
        out[outside] = np.nan
        return out.reshape(shape)

    def elevation_at_lonlat(self, lon: float, lat: float) -> float:
        return float(self.elevation(np.array([lon]), np.array([lat]), 4326)[0])

    def intersect(self, altitude_m: float, origin_en: tuple[float, float], directions: np.ndarray,
                  epsg: int) -> np.ndarray:
        """Where rays from a camera at ``altitude_m`` over ``origin_en`` (map coordinates in
        ``epsg``) meet the terrain: (k, 3) easting, northing, height for (k, 3) map-frame
        directions (east, north, up; pointing down). A ray that leaves the DEM before it meets
        the ground is a DemError."""
        d = np.asarray(directions, np.float64)
        zlo, zhi = self.zrange
        dz = d[:, 2]
        t_hi = np.maximum((altitude_m - zhi) / -dz, 0.0)  # the ray is above all terrain before this
        t_lo = (altitude_m - zlo) / -dz + 1e-6  # ... and below all of it after this
        steps = t_hi[:, None] + (t_lo - t_hi)[:, None] * np.linspace(0.0, 1.0, _STEPS + 1)[None, :]

        def above(t: np.ndarray, k: np.ndarray) -> np.ndarray:
            e = origin_en[0] + t * d[k, 0]
            n = origin_en[1] + t * d[k, 1]
            ground = self.elevation(e, n, epsg)
            return altitude_m + t * d[k, 2] - ground  # NaN off the DEM

        k_all = np.repeat(np.arange(len(d))[:, None], _STEPS + 1, axis=1)
        gap = above(steps, k_all)
        # the last step is below the lowest terrain, so every ray has a first step not above the
        # ground, or one off the DEM (NaN), which is refused
        first = np.argmax(~(gap > 0), axis=1)
        idx = np.arange(len(d))
        if np.any(np.isnan(gap[idx, first])):
            raise DemError(f"{self.source}: part of the view leaves the DEM (or meets its no-data cells) before "
                           f"it meets the ground; use a DEM that covers the whole flight")
        lo = steps[idx, np.maximum(first - 1, 0)]
        hi = steps[idx, first]
        for _ in range(_BISECTIONS):
            mid = (lo + hi) / 2
            up = above(mid, idx) > 0
            lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
        t = (lo + hi) / 2
        e, n = origin_en[0] + t * d[:, 0], origin_en[1] + t * d[:, 1]
        return np.stack([e, n, altitude_m + t * d[:, 2]], axis=1)

    def describe(self) -> dict[str, Any]:
        zlo, zhi = self.zrange
        rows, cols = self.heights.shape
        return {"dem": self.source, "dem_size": [cols, rows], "dem_elevation_range_m": [round(zlo, 2), round(zhi, 2)],
                "dem_cell": [abs(self.transform[1]), abs(self.transform[5])]}

