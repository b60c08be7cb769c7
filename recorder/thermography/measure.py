"""Measurement tools on a frame's temperatures.

A tool is a spot, a box, a line or a polygon in pixel coordinates (x to the right, y down,
pixel (x, y) covering [x, x+1) x [y, y+1)). A box is inclusive of both corners, as detector
boxes are. A polygon holds the pixels whose centres lie inside it (even-odd rule), so two
polygons sharing an edge never both count a pixel. A line samples the pixels its centre line
crosses, one sample per pixel step, nearest pixel. Statistics ignore NaN (a model's "no
temperature"); a region with no finite pixel says so instead of giving a number.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["Box", "Line", "Measurement", "Polygon", "Spot", "Tool", "ToolError", "bounds", "histogram", "isotherm",
           "line_profile", "measure", "parse_tool", "shifted"]


class ToolError(ValueError):
    """A tool that does not fit the frame or does not parse (the message says how)."""


@dataclass(frozen=True)
class Spot:
    x: int
    y: int


@dataclass(frozen=True)
class Box:
    x0: int
    y0: int
    x1: int
    y1: int


@dataclass(frozen=True)
class Line:
    x0: float
    y0: float
    x1: float
    y1: float


@dataclass(frozen=True)
class Polygon:
    points: tuple[tuple[float, float], ...]


Tool = Spot | Box | Line | Polygon


def parse_tool(text: str) -> Tool:
    """``spot:x,y``, ``box:x0,y0,x1,y1``, ``line:x0,y0,x1,y1``, ``polygon:x0,y0,x1,y1,x2,y2,...``."""
    kind, _, rest = text.partition(":")
    try:
        nums = [float(v) for v in rest.split(",")] if rest else []
    except ValueError:
        raise ToolError(f"tool {text!r}: coordinates must be numbers") from None
    if not all(math.isfinite(v) and abs(v) < 1e9 for v in nums):
        raise ToolError(f"tool {text!r}: coordinates must be finite pixel positions")
    if kind == "spot" and len(nums) == 2:
        return Spot(int(nums[0]), int(nums[1]))
    if kind == "box" and len(nums) == 4:
        x0, y0, x1, y1 = (int(v) for v in nums)
        return Box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))
    if kind == "line" and len(nums) == 4:
        return Line(*nums)
    if kind == "polygon" and len(nums) >= 6 and len(nums) % 2 == 0:
        return Polygon(tuple(zip(nums[::2], nums[1::2], strict=True)))
    raise ToolError(f"tool {text!r}: use spot:x,y, box:x0,y0,x1,y1, line:x0,y0,x1,y1 or "
                    f"polygon:x0,y0,x1,y1,x2,y2[,...]")


def bounds(tool: Tool, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """The tool's pixel rectangle (x0, y0, x1, y1 exclusive), clipped to the frame: the only part
    of a frame a statistic of the tool needs converted to °C. A spot or box that leaves the frame
    is a ToolError, as ``measure`` says it."""
    h, w = shape
    if isinstance(tool, Spot | Box):
        x0, y0, x1, y1 = (tool.x, tool.y, tool.x + 1, tool.y + 1) if isinstance(tool, Spot) else \
            (tool.x0, tool.y0, tool.x1 + 1, tool.y1 + 1)
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            _mask(shape, tool)  # raises, with the message measure gives
    elif isinstance(tool, Line):
        x0, x1 = math.floor(min(tool.x0, tool.x1)), math.floor(max(tool.x0, tool.x1)) + 1
        y0, y1 = math.floor(min(tool.y0, tool.y1)), math.floor(max(tool.y0, tool.y1)) + 1
    else:
        xs, ys = [p[0] for p in tool.points], [p[1] for p in tool.points]
        x0, x1, y0, y1 = math.floor(min(xs)), math.ceil(max(xs)) + 1, math.floor(min(ys)), math.ceil(max(ys)) + 1
    return max(0, x0), max(0, y0), min(w, x1), min(h, y1)


def shifted(tool: Tool, dx: int, dy: int) -> Tool:
    """The same tool in a crop that starts at (dx, dy)."""
    if isinstance(tool, Spot):
        return Spot(tool.x - dx, tool.y - dy)
    if isinstance(tool, Box):
        return Box(tool.x0 - dx, tool.y0 - dy, tool.x1 - dx, tool.y1 - dy)
    if isinstance(tool, Line):
        return Line(tool.x0 - dx, tool.y0 - dy, tool.x1 - dx, tool.y1 - dy)
    return Polygon(tuple((x - dx, y - dy) for x, y in tool.points))


def _polygon_mask(shape: tuple[int, int], points: tuple[tuple[float, float], ...]) -> np.ndarray:
    h, w = shape
    xs, ys = np.arange(w) + 0.5, np.arange(h) + 0.5
    px, py = np.meshgrid(xs, ys)
    inside = np.zeros(shape, bool)
    n = len(points)
    for i in range(n):
        (xa, ya), (xb, yb) = points[i], points[(i + 1) % n]
        if ya == yb:
            continue
        crosses = (py >= min(ya, yb)) & (py < max(ya, yb))
        x_at = xa + (py - ya) * (xb - xa) / (yb - ya)
        inside ^= crosses & (px < x_at)
    return inside


def _mask(shape: tuple[int, int], tool: Tool) -> np.ndarray:
    h, w = shape
    mask = np.zeros(shape, bool)
    if isinstance(tool, Spot):
        if not (0 <= tool.x < w and 0 <= tool.y < h):
            raise ToolError(f"spot ({tool.x}, {tool.y}) is outside the {w}x{h} frame")
        mask[tool.y, tool.x] = True
    elif isinstance(tool, Box):
        if tool.x0 < 0 or tool.y0 < 0 or tool.x1 >= w or tool.y1 >= h:
            raise ToolError(f"box {tool.x0},{tool.y0}..{tool.x1},{tool.y1} is outside the {w}x{h} frame")
        mask[tool.y0:tool.y1 + 1, tool.x0:tool.x1 + 1] = True
    elif isinstance(tool, Polygon):
        mask = _polygon_mask(shape, tool.points)
    elif isinstance(tool, Line):
        for x, y in _line_pixels(shape, tool):
            mask[y, x] = True
    if not mask.any():
        raise ToolError(f"{type(tool).__name__.lower()} holds no pixel of the {w}x{h} frame")
    return mask


@dataclass(frozen=True)
class Measurement:
    tool: str
    pixels: int
    min_c: float | None
    max_c: float | None
    mean_c: float | None
    std_c: float | None
    max_xy: tuple[int, int] | None
    min_xy: tuple[int, int] | None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _r(v: float) -> float:
    return round(float(v), 4)


def measure(temps: np.ndarray, tool: Tool, label: str | None = None) -> Measurement:
    mask = _mask(temps.shape, tool)
    vals = np.where(mask, temps, np.nan)
    finite = np.isfinite(vals)
    name = label or type(tool).__name__.lower()
    if not finite.any():
        return Measurement(name, int(mask.sum()), None, None, None, None, None, None)
    imax = np.unravel_index(int(np.nanargmax(vals)), vals.shape)
    imin = np.unravel_index(int(np.nanargmin(vals)), vals.shape)
    v = vals[finite].astype(np.float64)
    return Measurement(name, int(mask.sum()), _r(v.min()), _r(v.max()), _r(v.mean()), _r(v.std()),
                       (int(imax[1]), int(imax[0])), (int(imin[1]), int(imin[0])))


def _line_pixels(shape: tuple[int, int], line: Line) -> list[tuple[int, int]]:
    h, w = shape
    steps = max(1, math.ceil(max(abs(line.x1 - line.x0), abs(line.y1 - line.y0))))
    out: list[tuple[int, int]] = []
    for i in range(steps + 1):
        x = line.x0 + (line.x1 - line.x0) * i / steps
        y = line.y0 + (line.y1 - line.y0) * i / steps
        px, py = min(w - 1, max(0, math.floor(x))), min(h - 1, max(0, math.floor(y)))
        if not (0 <= x <= w and 0 <= y <= h):
            raise ToolError(f"line point ({x:.1f}, {y:.1f}) is outside the {w}x{h} frame")
        if not out or out[-1] != (px, py):
            out.append((px, py))
    return out


def line_profile(temps: np.ndarray, line: Line) -> list[dict[str, Any]]:
    """Temperature along a line: (distance from its start in pixels, x, y, °C)."""
    out = []
    for x, y in _line_pixels(temps.shape, line):
        v = float(temps[y, x])
        out.append({"distance_px": _r(math.hypot(x + 0.5 - line.x0, y + 0.5 - line.y0)), "x": x, "y": y,
                    "celsius": _r(v) if math.isfinite(v) else None})
    return out


def histogram(temps: np.ndarray, bins: int = 64, lo: float | None = None, hi: float | None = None,
              tool: Tool | None = None) -> dict[str, Any]:
    vals = temps[_mask(temps.shape, tool)] if tool is not None else temps.ravel()
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return {"counts": [], "edges_c": [], "pixels": 0}
    a = float(vals.min()) if lo is None else lo
    b = float(vals.max()) if hi is None else hi
    if b <= a:
        b = a + 1e-3
    counts, edges = np.histogram(vals, bins=bins, range=(a, b))
    return {"counts": counts.tolist(), "edges_c": [_r(e) for e in edges], "pixels": int(vals.size)}


def isotherm(temps: np.ndarray, above: float | None = None, below: float | None = None) -> np.ndarray:
    """Pixels at or above ``above`` and/or at or below ``below`` (between, with both)."""
    if above is None and below is None:
        raise ToolError("an isotherm needs above and/or below (°C)")
    mask = np.isfinite(temps)
    if above is not None:
        mask &= temps >= above
    if below is not None:
        mask &= temps <= below
    return mask
