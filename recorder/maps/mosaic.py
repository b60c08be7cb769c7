"""A temperature mosaic of a flight's near-nadir images on one UTM grid.

Blending rule: each mosaic cell takes the pixel nearest to it from the image whose centre is
nearest to the cell, among the images that see it. So every mosaic value is one real
measurement of one frame, never an average of two; ``sources`` says which frame (-1: none).
Cells are ``gsd`` metres (the flight's median ground sample distance unless given). A flight
that crosses a UTM zone boundary is mosaicked on the grid of the zone most of its images are in:
the others' footprints are computed again on that grid (``footprint(..., epsg=)``), which is
exact, only with a larger grid convergence, rather than joined from two grids that do not meet.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from thermcap.recorder.maps.footprint import Footprint, footprint, pixel_to_ground

__all__ = ["Mosaic", "build_mosaic", "hot_spot_points"]


@dataclass
class Mosaic:
    temps: np.ndarray  # (rows, cols) float32 °C, NaN where no image sees the cell
    sources: np.ndarray  # (rows, cols) int32 frame index, -1 where none
    geotransform: tuple[float, float, float, float, float, float]  # north-up
    epsg: int
    gsd_m: float
    frames: list[int]


def _inverse_map(fp: Footprint, east: np.ndarray, north: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image (col, row) of ground points for a near-nadir image: the affine inverse of its
    geotransform (exact for nadir; near nadir within the tolerance the footprint allows)."""
    e0, a, b, n0, c, d = fp.geotransform()
    det = a * d - b * c
    de, dn = east - e0, north - n0
    return (d * de - b * dn) / det, (-c * de + a * dn) / det


def build_mosaic(images: list[tuple[int, Footprint, np.ndarray]], gsd_m: float | None = None,
                 max_cells: int = 40_000_000) -> Mosaic:
    """``images``: (frame index, its near-nadir footprint, its °C array)."""
    if not images:
        raise ValueError("no near-nadir image to mosaic")
    zone = Counter(fp.epsg for _, fp, _ in images).most_common(1)[0][0]
    images = [(i, fp if fp.epsg == zone else footprint(fp.pose, epsg=zone, dem=fp.dem), t) for i, fp, t in images]
    gsd = gsd_m or float(np.median([fp.gsd_m for _, fp, _ in images]))
    es = [e for _, fp, _ in images for e, _ in fp.corners_en]
    ns = [n for _, fp, _ in images for _, n in fp.corners_en]
    e0, n0 = math.floor(min(es) / gsd) * gsd, math.ceil(max(ns) / gsd) * gsd
    cols, rows = math.ceil((max(es) - e0) / gsd), math.ceil((n0 - min(ns)) / gsd)
    if rows * cols > max_cells:
        raise ValueError(f"a {cols}x{rows} mosaic at {gsd:.3f} m is too large; give a coarser gsd")
    east = e0 + (np.arange(cols) + 0.5) * gsd
    north = n0 - (np.arange(rows) + 0.5) * gsd
    ee, nn = np.meshgrid(east, north)
    temps = np.full((rows, cols), np.nan, np.float32)
    sources = np.full((rows, cols), -1, np.int32)
    best = np.full((rows, cols), np.inf)
    for index, fp, t in images:
        c, r = _inverse_map(fp, ee, nn)
        h, w = t.shape
        inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        dist = (c - w / 2) ** 2 + (r - h / 2) ** 2  # nearest image centre wins
        take = inside & (dist < best)
        ci = np.clip(np.floor(c[take]).astype(np.int64), 0, w - 1)
        ri = np.clip(np.floor(r[take]).astype(np.int64), 0, h - 1)
        temps[take] = t[ri, ci]
        sources[take] = index
        best[take] = dist[take]
    return Mosaic(temps, sources, (e0, gsd, 0.0, n0, 0.0, -gsd), zone, gsd, [i for i, _, _ in images])


def hot_spot_points(fp: Footprint, targets: list[dict[str, Any]],
                    celsius: np.ndarray | None = None) -> list[dict[str, Any]]:
    """Detected targets as map points: each target's centroid through the footprint. With
    ``celsius`` (the frame's temperatures in the model version asked for, bad pixels NaN), a
    target's ``max_temp_c`` is measured again over its box: the detector's figure is of the
    model at capture, kept as ``max_temp_c_at_capture``."""
    from pyproj import Transformer

    to_ll = Transformer.from_crs(fp.epsg, 4326, always_xy=True)
    out = []
    for t in targets:
        cen = t.get("centroid")
        if not cen or len(cen) != 2:
            continue
        e, n = pixel_to_ground(fp, np.array([float(cen[0]) + 0.5]), np.array([float(cen[1]) + 0.5]))
        lon, lat = to_ll.transform(float(e[0]), float(n[0]))
        hottest = t.get("max_temp_c")
        box = t.get("bbox")
        if celsius is not None and box and len(box) == 4:
            x0, y0, x1, y1 = (int(v) for v in box)
            region = celsius[max(0, y0):y1 + 1, max(0, x0):x1 + 1]
            hottest = round(float(np.nanmax(region)), 4) if region.size and np.isfinite(region).any() else None
        out.append({"easting": float(e[0]), "northing": float(n[0]), "epsg": fp.epsg, "longitude": lon,
                    "latitude": lat,
                    "target_id": t.get("target_id"), "max_temp_c": hottest,
                    **({"max_temp_c_at_capture": t.get("max_temp_c")} if celsius is not None else {}),
                    "classification": t.get("classification"), "uncertainty_m": round(fp.uncertainty_m, 2)})
    return out

