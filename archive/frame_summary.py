"""``archive/summary.npz``: each frame's count statistics and row-band checksums, taken on the
archive's one read of the source.

Why it exists: a region's time series over an hour (216,000 frames) must not decode every frame.

- The whole frame's min and max (and its mean, where the model is affine) come straight from
  here. A radiometric model maps each count on its own, and it is monotonic over the counts a
  session holds (checked, not assumed), so the extreme count gives the extreme temperature.
- A box decodes only the TIFF strips its rows fall in. Each strip's rows are checked against
  their band's CRC-32 here before they are used, so a partial read is checked as a whole
  frame is. The ZIP directory's CRC-32 plays the same part for served PNGs. This file is in
  turn bound to the manifest by its digest.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import imagecodecs
import numpy as np

from thermcap.recorder.storage.layout import SUMMARY_NAME

__all__ = ["BAND_ROWS", "SUMMARY_NAME", "FrameSummary", "SummaryBuilder", "band_crc32", "load_summary"]

#: Rows per checksum band: the tiff-lzw format's strip height, so a strip is checked alone.
BAND_ROWS = 64


def band_crc32(pixels: np.ndarray, band_rows: int = BAND_ROWS) -> np.ndarray:
    """CRC-32 of each band of ``band_rows`` rows (the last may be shorter), over the uint16 LE
    bytes, the same bytes the frame's digest covers. libdeflate's CRC-32 (the same value as
    zlib's) runs at about 28 GB/s where zlib's runs at 5: 0.03 ms a 640x512 frame, not 0.12."""
    arr = np.ascontiguousarray(pixels, dtype="<u2")
    crc = imagecodecs.deflate_crc32
    bands = range(0, arr.shape[0], band_rows)
    return np.array([crc(cast(bytes, arr[y:y + band_rows])) for y in bands], dtype=np.uint32)


@dataclass(frozen=True)
class FrameSummary:
    """One row per frame, in session order."""

    band_rows: int
    width: int
    height: int
    min: np.ndarray  # uint16 [n]
    max: np.ndarray  # uint16 [n]
    sum: np.ndarray  # uint64 [n]: the mean is sum / (width * height)
    band_crc32: np.ndarray  # uint32 [n, bands]

    @property
    def frames(self) -> int:
        return len(self.min)

    def checkable(self, y0: int, nrows: int) -> bool:
        """Whether rows ``y0 .. y0+nrows`` are whole bands (or end with the frame), so their
        checksums can be compared at all."""
        end = y0 + nrows
        return y0 % self.band_rows == 0 and (end % self.band_rows == 0 or end == self.height) and end <= self.height

    def rows_intact(self, index: int, y0: int, rows: np.ndarray) -> bool:
        """Whether ``rows`` (a ``checkable`` run starting at row ``y0``) are the recorded ones."""
        if not self.checkable(y0, rows.shape[0]) or index >= self.frames or rows.shape[1:] != (self.width,):
            return False
        b = y0 // self.band_rows
        want = self.band_crc32[index, b: b + -(-rows.shape[0] // self.band_rows)]
        return bool(np.array_equal(band_crc32(rows, self.band_rows), want))

    def celsius(self, stat: str, indices: np.ndarray, to_celsius: Callable[[np.ndarray], np.ndarray]) -> \
            list[float] | None:
        """The whole frame's ``stat`` in °C for frames ``indices``, or None where this summary
        cannot give it exactly: the model must be finite and non-decreasing over the counts
        these frames hold (then the extreme count is the extreme temperature), and for the
        mean, affine there too (then the mean temperature is the model of the mean count).
        Values are rounded as the measurement tools round them."""
        lo, hi = int(self.min[indices].min()), int(self.max[indices].max())
        lut = np.asarray(to_celsius(np.arange(lo, hi + 1, dtype=np.uint16)), dtype=np.float32).astype(np.float64)
        if not np.isfinite(lut).all() or (lut.size > 1 and bool((np.diff(lut) < 0).any())):
            return None
        if stat in ("max", "min"):
            vals = lut[(self.max if stat == "max" else self.min)[indices].astype(np.int64) - lo]
        elif stat == "mean":
            slope = (lut[-1] - lut[0]) / (hi - lo) if hi > lo else 0.0
            if float(np.abs(lut - (lut[0] + slope * np.arange(lut.size))).max(initial=0.0)) > 1e-4:
                return None
            vals = lut[0] + slope * (self.sum[indices].astype(np.float64) / (self.width * self.height) - lo)
        else:
            raise ValueError(f"stat must be max, mean or min, got {stat!r}")
        return [round(float(v), 4) for v in vals]

    def to_bytes(self) -> bytes:
        buf = io.BytesIO()
        np.savez(buf, band_rows=np.int64(self.band_rows), shape=np.array([self.height, self.width], np.int64),
                 min=self.min, max=self.max, sum=self.sum, band_crc32=self.band_crc32)
        return buf.getvalue()

    def save(self, path: Path) -> None:
        """Atomically: a crash leaves the old file or none, never half of one."""
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as f:
            f.write(self.to_bytes())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)


def load_summary(data: bytes, *, name: str = SUMMARY_NAME) -> FrameSummary:
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            h, w = (int(v) for v in z["shape"])
            out = FrameSummary(int(z["band_rows"]), w, h, z["min"], z["max"], z["sum"], z["band_crc32"])
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"{name}: not a frame summary ({exc})") from exc
    n = out.frames
    if not (len(out.max) == len(out.sum) == out.band_crc32.shape[0] == n):
        raise ValueError(f"{name}: its arrays disagree on the number of frames")
    return out


class SummaryBuilder:
    """Fed every frame of the source pass; preallocated, since the source's summaries say how
    many frames there are (a frame beyond that grows the arrays)."""

    def __init__(self, expected_frames: int = 0, band_rows: int = BAND_ROWS) -> None:
        self.band_rows = band_rows
        self.n = 0
        self._min = np.zeros(expected_frames, np.uint16)
        self._max = np.zeros(expected_frames, np.uint16)
        self._sum = np.zeros(expected_frames, np.uint64)
        self._crc: np.ndarray | None = None
        self.shape = (0, 0)

    def add(self, pixels: np.ndarray) -> None:
        if self.n == 0:
            self.shape = pixels.shape[:2]
            self._crc = np.zeros((len(self._min), -(-self.shape[0] // self.band_rows)), np.uint32)
        elif pixels.shape[:2] != self.shape:
            raise ValueError(f"frame {self.n} is {pixels.shape[1]}x{pixels.shape[0]}, the session's first was "
                             f"{self.shape[1]}x{self.shape[0]}")
        assert self._crc is not None
        if self.n == len(self._min):
            grow = max(1024, self.n)
            self._min, self._max, self._sum = (np.concatenate([a, np.zeros(grow, a.dtype)])
                                               for a in (self._min, self._max, self._sum))
            self._crc = np.concatenate([self._crc, np.zeros((grow, self._crc.shape[1]), np.uint32)])
        if pixels.ndim == 2 and pixels.dtype == np.uint16 and pixels.size:
            from thermcap.archive.summary_kernels import frame_stats  # numba: imported on first use

            self._min[self.n], self._max[self.n], self._sum[self.n] = frame_stats(pixels)
        else:
            self._min[self.n] = pixels.min()
            self._max[self.n] = pixels.max()
            self._sum[self.n] = int(pixels.sum(dtype=np.uint64))
        self._crc[self.n] = band_crc32(pixels, self.band_rows)
        self.n += 1

    def finish(self) -> FrameSummary:
        n = self.n
        crc = self._crc[:n] if self._crc is not None else np.zeros((0, 0), np.uint32)
        return FrameSummary(self.band_rows, int(self.shape[1]), int(self.shape[0]), self._min[:n].copy(),
                            self._max[:n].copy(), self._sum[:n].copy(), crc.copy())
