"""Turning counts into what people look at: temperatures, colour previews, image files."""

from __future__ import annotations

import io
import json
from functools import cache, lru_cache

import numpy as np
import tifffile

from thermcap.recorder.exports.colorbar import TemperatureRange, add_colorbar
from thermcap.recorder.exports.percentiles import percentiles
from thermcap.recorder.exports.png import encode_png
from thermcap.recorder.radiometry import RadiometricModel, model_from_dict
from thermcap.recorder.radiometry.session import FrameTemperatures

__all__ = ["PALETTES", "celsius", "celsius_tiff", "colour_png", "frame_range", "palette", "preview_png",
           "session_model", "tiff16"]

PALETTES = ("ironbow", "gray", "turbo")


def _turbo(x: np.ndarray) -> np.ndarray:
    # Google's polynomial approximation of the Turbo colour map (Apache-2.0 constants).
    r = 0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))))
    g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))))
    b = 0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))))
    return np.stack([r, g, b], axis=-1)


@cache
def palette(name: str) -> np.ndarray:
    """A (256, 3) uint8 lookup table."""
    x = np.linspace(0.0, 1.0, 256)
    if name == "gray":
        rgb = np.stack([x, x, x], axis=-1)
    elif name == "turbo":
        rgb = _turbo(x)
    elif name == "ironbow":
        keys = np.array([0.0, 0.15, 0.35, 0.55, 0.75, 0.9, 1.0])
        cols = np.array([[0, 0, 0], [32, 0, 96], [128, 0, 160], [208, 48, 64], [240, 128, 0], [255, 208, 32],
                         [255, 255, 240]]) / 255.0
        rgb = np.stack([np.interp(x, keys, cols[:, i]) for i in range(3)], axis=-1)
    else:
        raise ValueError(f"unknown palette {name!r}; use one of {', '.join(PALETTES)}")
    return (np.clip(rgb, 0, 1) * 255).round().astype(np.uint8)


@lru_cache(maxsize=64)
def session_model(model_json: str | None) -> RadiometricModel:
    """Models are immutable, so one parse per distinct JSON (a DJI lookup table is thousands of entries)."""
    return model_from_dict(json.loads(model_json) if model_json else {"kind": "linear"})


def celsius(frame: np.ndarray, model: RadiometricModel) -> np.ndarray:
    return np.asarray(model.to_celsius(frame), dtype=np.float32)


def frame_range(values: np.ndarray, mode: str = "frame", units: str = "°C") -> TemperatureRange:
    """The 0.5..99.5 percentiles: a few hot or dead pixels do not wash out the picture."""
    lo, hi = percentiles(values, (0.5, 99.5))
    return TemperatureRange(lo, hi if hi > lo else lo + 1e-3, mode, units)


#: Pixels without a temperature (the session's bad pixels) in a picture: magenta, off every palette.
NO_TEMPERATURE_RGB = (255, 0, 255)


def colour_png(values: np.ndarray, rng: TemperatureRange, palette_name: str = "ironbow", *,
               colorbar: bool = True, level: int = 1, boxes: list[list[int]] | tuple = (),
               text: dict[str, str] | None = None) -> bytes:
    """Values (°C, or counts) as an 8-bit colour PNG on ``rng``, with ``boxes`` (inclusive pixel
    boxes, e.g. detections) outlined in white: a colour bar drawn in, for people; always the
    range in its text chunks, for programs, with ``text`` beside it (the model version used)."""
    lut = palette(palette_name)
    missing = np.isnan(values) if values.dtype.kind == "f" else None
    if missing is not None and missing.any():
        values = np.where(missing, rng.lo, values)
    else:
        missing = None
    idx = np.clip((values - rng.lo) * (255.0 / max(rng.hi - rng.lo, 1e-6)), 0, 255).astype(np.uint8)
    rgb = np.take(lut, idx, axis=0)  # lut[idx], a third of the time (1.4 against 4.5 ms at 640x512)
    if missing is not None:
        rgb[missing] = NO_TEMPERATURE_RGB  # a known bad pixel: no temperature, never a colour of the scale
    h, w = values.shape
    for x0, y0, x1, y1 in boxes:
        x0, y0, x1, y1 = max(0, x0 - 1), max(0, y0 - 1), min(w - 1, x1 + 1), min(h - 1, y1 + 1)
        rgb[y0, x0:x1 + 1] = rgb[y1, x0:x1 + 1] = 255
        rgb[y0:y1 + 1, x0] = rgb[y0:y1 + 1, x1] = 255
    if colorbar:
        rgb = add_colorbar(rgb, rng, lut)
    return encode_png(rgb, level, {**rng.text(), **(text or {})})


def preview_png(frame: np.ndarray, model: RadiometricModel, palette_name: str = "ironbow",
                t_min: float | None = None, t_max: float | None = None, *, colorbar: bool = True,
                session_range: TemperatureRange | None = None) -> tuple[bytes, TemperatureRange]:
    """8-bit colour PNG and its scale: the frame's own range, ``session_range``, or the fixed
    ``t_min``..``t_max`` (°C). Where the model cannot give temperatures (DJI layouts that need
    DJI's SDK) the counts are stretched, and the scale says counts."""
    from thermcap.recorder.radiometry import TemperatureUnavailable

    try:
        values, units = celsius(frame, model), "°C"
    except TemperatureUnavailable:
        values, units, t_min, t_max, session_range = frame.astype(np.float32), "counts", None, None, None
    if t_min is not None and t_max is not None:
        rng = TemperatureRange(t_min, t_max, "fixed", units)
    elif session_range is not None:
        rng = session_range
    else:
        rng = frame_range(values, "frame", units)
    return colour_png(values, rng, palette_name, colorbar=colorbar), rng


def tiff16(frame: np.ndarray, description: str | None = None) -> bytes:
    buf = io.BytesIO()
    tifffile.imwrite(buf, np.ascontiguousarray(frame, dtype=np.uint16), byteorder="<", photometric="minisblack",
                     description=description, metadata=None)
    return buf.getvalue()


def celsius_tiff(temps: FrameTemperatures) -> bytes:
    """A °C GeoTIFF of one frame's ``FrameTemperatures`` (``recorder.radiometry.session``), naming
    the model version and the bad-pixel rule it used (see ``recorder.exports.geotiff``)."""
    from thermcap.recorder.exports.geotiff import write_temperature_tiff

    buf = io.BytesIO()
    said = temps.describe()
    write_temperature_tiff(buf, temps.celsius, units="degC", metadata=said,
                           description=json.dumps({"units": "degC", **said}))
    return buf.getvalue()
