"""Temperature GeoTIFFs that GDAL, QGIS and rasterio read as what they are.

Float32 °C (or K), with GDAL's own tags: ``GDAL_METADATA`` (the band's unit, the radiometric
model, the session and frame) and ``GDAL_NODATA`` (NaN, where a model has no temperature);
DEFLATE with the floating-point predictor, in 256x256 tiles; where the frame's position is
known, the GeoTIFF keys of ``geotiff_tags``. ``cog=True`` writes a Cloud-Optimized GeoTIFF with
GDAL's COG driver (through rasterio, the optional ``geo`` extra), same content.
"""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import numpy as np
import tifffile

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.install_hint import install_command

__all__ = ["gcp_tags", "gdal_metadata_xml", "geotransform_tags", "utm_tags", "write_cog", "write_temperature_tiff"]

GDAL_METADATA, GDAL_NODATA = 42112, 42113


def gdal_metadata_xml(items: dict[str, Any], units: str) -> str:
    rows = [f'<Item name="{escape(k)}">{escape(v if isinstance(v, str) else json.dumps(v))}</Item>'
            for k, v in items.items() if v is not None]
    rows.append(f'<Item name="UNITTYPE" sample="0" role="unittype">{escape(units)}</Item>')
    if items.get("temperature_quality"):  # GDAL and QGIS show a band's description beside its values
        rows.append(f'<Item name="DESCRIPTION" sample="0" role="description">temperature, '
                    f'{escape(str(items["temperature_quality"]))}</Item>')
    return "<GDALMetadata>" + "".join(rows) + "</GDALMetadata>"


def _geokeys(epsg: int) -> tuple[int, ...]:
    if epsg == 4326:  # geographic WGS 84, PixelIsArea
        return (1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326)
    return (1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, epsg)  # projected, PixelIsArea


def geotransform_tags(gt: Sequence[float], epsg: int) -> list[tuple]:
    """GDAL's six-term geotransform (rotation included) as a ModelTransformation and GeoKeys."""
    e0, de_c, de_r, n0, dn_c, dn_r = gt
    matrix = (de_c, de_r, 0.0, e0, dn_c, dn_r, 0.0, n0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    keys = _geokeys(epsg)
    return [(34264, "d", 16, matrix, True), (34735, "H", len(keys), keys, True)]


def gcp_tags(pixels: Sequence[tuple[float, float]], coords: Sequence[tuple[float, float]], epsg: int) -> list[tuple]:
    """Tie points (column, row) -> (x, y), which GDAL reads as GCPs."""
    ties: list[float] = []
    for (c, r), (x, y) in zip(pixels, coords, strict=True):
        ties += [c, r, 0.0, x, y, 0.0]
    keys = _geokeys(epsg)
    return [(33922, "d", len(ties), tuple(ties), True), (34735, "H", len(keys), keys, True)]


def utm_tags(fp: Any) -> list[tuple]:
    """GeoTIFF tags placing an image by its footprint (``recorder.maps.footprint``) in its UTM
    zone: near nadir an affine ModelTransformation (rotation included); oblique, the four
    corners as tie points, which GDAL reads as GCPs."""
    if fp.nadir:
        return geotransform_tags(fp.geotransform(), fp.epsg)
    w, h = fp.pose.width, fp.pose.height
    return gcp_tags([(0.0, 0.0), (float(w), 0.0), (float(w), float(h)), (0.0, float(h))], fp.corners_en, fp.epsg)


def _tile(shape: tuple[int, ...]) -> tuple[int, int] | None:
    h, w = shape
    if h < 16 or w < 16:
        return None  # too small to tile: one strip
    return min(256, h // 16 * 16), min(256, w // 16 * 16)


def write_temperature_tiff(target: str | Path | io.BytesIO, data: np.ndarray, *, units: str,
                           metadata: dict[str, Any], description: str | None = None,
                           geo_tags: Sequence[tuple] = (), position: dict[str, Any] | None = None,
                           cog: bool = False) -> None:
    data = np.ascontiguousarray(data, dtype=np.float32)
    if cog:
        _write_cog(target, data, units=units, metadata=metadata, description=description, position=position)
        return
    extratags = [(GDAL_METADATA, "s", 0, gdal_metadata_xml(metadata, units), True),
                 (GDAL_NODATA, "s", 0, "nan", True), *geo_tags]
    tifffile.imwrite(target, data, photometric="minisblack", byteorder="<", metadata=None, description=description,
                     compression="zlib", predictor=True, tile=_tile(data.shape), extratags=extratags)


def write_cog(path: str | Path, data: np.ndarray, *, geotransform: Sequence[float], epsg: int,
              units: str | None, metadata: dict[str, Any], nodata: float | int) -> None:
    """A north-up Cloud-Optimized GeoTIFF on a map grid (a mosaic and its companions)."""
    try:
        import rasterio
        from rasterio.crs import CRS
        from rasterio.transform import Affine
    except ImportError:
        raise ThermcapError(f"a Cloud-Optimized GeoTIFF needs rasterio ({install_command('maps')})") from None
    h, w = data.shape
    e0, a, b, n0, c, d = geotransform
    profile: dict[str, Any] = {"driver": "COG", "width": w, "height": h, "count": 1, "dtype": str(data.dtype),
                               "nodata": nodata, "compress": "DEFLATE",
                               "predictor": 3 if data.dtype.kind == "f" else 2,
                               "blocksize": 256 if min(h, w) >= 256 else 128,
                               "crs": CRS.from_epsg(epsg), "transform": Affine(a, b, e0, c, d, n0)}
    with rasterio.Env(), rasterio.open(str(path), "w", **profile) as dst:
        dst.write(data, 1)
        dst.update_tags(**{k: v if isinstance(v, str) else json.dumps(v) for k, v in metadata.items()
                           if v is not None})
        if units:
            dst.units = (units,)


def _write_cog(target: str | Path | io.BytesIO, data: np.ndarray, *, units: str, metadata: dict[str, Any],
               description: str | None, position: dict[str, Any] | None) -> None:
    try:
        import rasterio
        from rasterio.control import GroundControlPoint
        from rasterio.crs import CRS
        from rasterio.errors import NotGeoreferencedWarning
    except ImportError:
        raise ThermcapError(f"a Cloud-Optimized GeoTIFF needs rasterio ({install_command('maps')})") from None
    h, w = data.shape
    profile: dict[str, Any] = {"driver": "COG", "width": w, "height": h, "count": 1, "dtype": "float32",
                               "nodata": float("nan"), "compress": "DEFLATE", "predictor": 3,
                               "blocksize": 256 if min(h, w) >= 256 else 128}
    gcps = None
    if position is not None and position.get("crs") == "EPSG:4326":
        gcps = [GroundControlPoint(row=h / 2.0, col=w / 2.0, x=float(position["longitude"]),
                                   y=float(position["latitude"]), z=float(position.get("absolute_altitude_m") or 0))]
    if isinstance(target, io.BytesIO):
        raise ThermcapError("a Cloud-Optimized GeoTIFF is written to a file, not to memory")
    with warnings.catch_warnings():
        # rasterio warns at the open that the new file has no grid: a frame without a position
        # never gets one (it is on no map), one with a position gets its ground control point below
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.Env(), rasterio.open(str(target), "w", **profile) as dst:
            dst.write(data, 1)
            dst.update_tags(**{k: v if isinstance(v, str) else json.dumps(v) for k, v in metadata.items()
                               if v is not None})
            if description:
                dst.update_tags(TIFFTAG_IMAGEDESCRIPTION=description)
            dst.units = (units,)
            if gcps:
                dst.gcps = (gcps, CRS.from_epsg(4326))
