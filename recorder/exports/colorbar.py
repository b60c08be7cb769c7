"""A °C scale on every picture: a colour bar with labelled ticks drawn into the image (for
people), and the range in PNG text chunks (for programs).

The labels use a built-in 5x7 pixel font, so drawing needs no font files or imaging library
and looks the same on every machine. ``recorder.exports.png`` writes the ``tEXt`` chunks after IHDR, where
any PNG reader (libpng, Pillow, browsers) ignores or exposes them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

__all__ = ["RANGE_MODES", "TemperatureRange", "add_colorbar", "png_text"]

#: how the range of a picture is chosen: each frame's own percentiles, one range for the whole
#: session, or the user's fixed --min/--max
RANGE_MODES = ("frame", "session", "fixed")

_GLYPHS = {
    "0": ["01110", "10001", "10011", "10101", "11001", "10001", "01110"],
    "1": ["00100", "01100", "00100", "00100", "00100", "00100", "01110"],
    "2": ["01110", "10001", "00001", "00010", "00100", "01000", "11111"],
    "3": ["11110", "00001", "00001", "01110", "00001", "00001", "11110"],
    "4": ["00010", "00110", "01010", "10010", "11111", "00010", "00010"],
    "5": ["11111", "10000", "11110", "00001", "00001", "10001", "01110"],
    "6": ["00110", "01000", "10000", "11110", "10001", "10001", "01110"],
    "7": ["11111", "00001", "00010", "00100", "01000", "01000", "01000"],
    "8": ["01110", "10001", "10001", "01110", "10001", "10001", "01110"],
    "9": ["01110", "10001", "10001", "01111", "00001", "00010", "01100"],
    "-": ["00000", "00000", "00000", "11111", "00000", "00000", "00000"],
    ".": ["00000", "00000", "00000", "00000", "00000", "01100", "01100"],
    "°": ["01100", "10010", "10010", "01100", "00000", "00000", "00000"],
    "C": ["01110", "10001", "10000", "10000", "10000", "10001", "01110"],
    "K": ["10001", "10010", "10100", "11000", "10100", "10010", "10001"],
    " ": ["00000"] * 7,
}


@dataclass(frozen=True)
class TemperatureRange:
    """The scale of a picture: ``lo`` maps to the first colour, ``hi`` to the last."""

    lo: float
    hi: float
    mode: str = "frame"
    units: str = "°C"

    def text(self) -> dict[str, str]:
        return {"thermcap:range_min": f"{self.lo:.4f}", "thermcap:range_max": f"{self.hi:.4f}",
                "thermcap:range_mode": self.mode, "thermcap:units": self.units.replace("°", "deg")}

    def headers(self) -> dict[str, str]:
        return {"X-Range-Min": f"{self.lo:.4f}", "X-Range-Max": f"{self.hi:.4f}", "X-Range-Mode": self.mode,
                "X-Range-Units": self.units.replace("°", "deg")}


def _label(text: str, scale: int) -> np.ndarray:
    cols = [np.array([[c == "1" for c in row] for row in _GLYPHS.get(ch, _GLYPHS[" "])]) for ch in text]
    gap = np.zeros((7, 1), bool)
    mask = np.hstack([np.hstack([c, gap]) for c in cols])[:, :-1] if cols else np.zeros((7, 0), bool)
    return np.kron(mask, np.ones((scale, scale), bool))


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    step = (hi - lo) / (n - 1)
    return [lo + i * step for i in range(n)]


def _fmt(v: float, span: float) -> str:
    return f"{v:.0f}" if span >= 100 else f"{v:.1f}" if span >= 2 else f"{v:.2f}"


def add_colorbar(rgb: np.ndarray, rng: TemperatureRange, lut: np.ndarray) -> np.ndarray:
    """``rgb`` (H, W, 3) with a bar and tick labels appended on its right (same height)."""
    h = rgb.shape[0]
    scale = 1 if h < 240 else 2
    span = rng.hi - rng.lo
    labels = [_fmt(v, span) for v in _ticks(rng.lo, rng.hi)]
    unit = _label(rng.units if all(ch in _GLYPHS for ch in rng.units) else "", scale)
    label_w = max([_label(t, scale).shape[1] for t in labels] + [unit.shape[1]])
    bar_w = 6 * scale
    pad = 3 * scale
    width = pad + bar_w + pad + label_w + pad
    panel = np.full((h, width, 3), 24, np.uint8)
    top, bottom = 5 * scale + 7 * scale, h - 5 * scale  # room for the unit above, a half label below
    if bottom - top < 10:
        top, bottom = 0, h
    ys = np.arange(top, bottom)
    idx = np.clip(((bottom - 1 - ys) / max(1, bottom - 1 - top) * 255).round(), 0, 255).astype(np.uint8)
    panel[top:bottom, pad:pad + bar_w] = lut[idx][:, None, :]
    white = np.array([235, 235, 235], np.uint8)
    for text, v in zip(labels, _ticks(rng.lo, rng.hi), strict=True):
        y = round(bottom - 1 - (v - rng.lo) / (span or 1) * (bottom - 1 - top))
        panel[max(0, y):y + 1, pad + bar_w:pad + bar_w + pad] = white  # tick
        mask = _label(text, scale)
        y0 = int(np.clip(y - mask.shape[0] // 2, 0, h - mask.shape[0]))
        x0 = pad + bar_w + pad
        region = panel[y0:y0 + mask.shape[0], x0:x0 + mask.shape[1]]
        region[mask[:region.shape[0], :region.shape[1]]] = white
    if top > 0:
        region = panel[scale:scale + unit.shape[0], pad:pad + unit.shape[1]]
        region[unit[:region.shape[0], :region.shape[1]]] = white
    return np.concatenate([rgb, panel], axis=1)


def png_text(png: bytes) -> dict[str, str]:
    """The ``tEXt`` chunks of a PNG (what a program reads back)."""
    out, pos = {}, 8
    while pos + 8 <= len(png):
        n = struct.unpack(">I", png[pos:pos + 4])[0]
        kind = png[pos + 4:pos + 8]
        if kind == b"tEXt":
            k, _, v = png[pos + 8:pos + 8 + n].partition(b"\x00")
            out[k.decode("latin-1")] = v.decode("latin-1")
        if kind == b"IEND":
            break
        pos += 12 + n
    return out
