"""Models whose curves live in vendor code: DJI's layouts, and count -> temperature tables measured
by the vendor's own software."""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass
from itertools import pairwise
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.radiometry.base import TemperatureUnavailable, register_model

__all__ = ["DjiModel", "LookupTableModel"]


@register_model
@dataclass(frozen=True)
class DjiModel:
    """DJI R-JPEG layouts. For ``iirp`` the counts are 14-bit x 4 and ``(raw >> 2) / 16 - 273.15``
    is the *uncorrected* blackbody temperature (no emissivity, reflection or atmosphere): labelled
    ``approximate``, off from DJI's SDK by up to several degrees. ``dirp``, ``girp`` and ``hirp``
    need tables inside DJI's Thermal SDK: ``to_celsius`` refuses rather than print a wrong number."""

    kind: ClassVar[str] = "dji"
    layout: str = "iirp"
    emissivity: float | None = None
    distance_m: float | None = None
    humidity_pct: float | None = None
    reflection_c: float | None = None
    ambient_c: float | None = None
    bit_depth: int = 16

    @property
    def approximate(self) -> bool:
        return self.layout == "iirp"

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        if self.layout != "iirp":
            raise TemperatureUnavailable(
                f"DJI {self.layout} data: temperature needs the DJI Thermal SDK (its calibration blobs are kept "
                "with the session); thermcap does not guess. Import with --dji-sdk (dji-thermal-cli or libdirp) "
                "to have DJI's code measure it")
        return (np.asarray(raw).astype(np.uint16) >> 2) * 0.0625 - 273.15

    def to_dict(self) -> dict[str, Any]:
        out = {"kind": self.kind, **asdict(self)}
        out["temperature"] = ("approximate: uncorrected blackbody (raw>>2)/16-273.15, no emissivity/reflection/"
                              "atmosphere correction" if self.layout == "iirp" else "requires the DJI Thermal SDK")
        return out


@register_model
@dataclass(frozen=True)
class LookupTableModel:
    """A count -> temperature table measured by a vendor's own software (DJI's Thermal SDK through
    ``dji-thermal-cli`` or libdirp), for formats whose curves live in proprietary code.

    The vendor's output is checked at import to be a function of the stored count (it is, for every
    DJI layout on the samples), so the table is exact for the frames it came from; a count outside
    the table raises rather than interpolates. ``derived_from`` keeps the file's own model
    (layout, embedded parameters), ``source`` names the software and version that measured it.
    """

    kind: ClassVar[str] = "lookup_table"
    counts: tuple[int, ...]
    celsius: tuple[float, ...]
    source: str = ""
    derived_from: dict[str, Any] | None = None
    bit_depth: int = 16

    def __post_init__(self) -> None:
        counts = tuple(int(c) for c in self.counts)
        celsius = tuple(float(c) for c in self.celsius)
        if len(counts) != len(celsius) or not counts:
            raise ValueError(f"lookup table needs as many temperatures as counts, got {len(counts)} and {len(celsius)}")
        if any(b <= a for a, b in pairwise(counts)):
            raise ValueError("lookup table counts must be strictly increasing")
        if counts[0] < 0 or counts[-1] > 0xFFFF:
            raise ValueError("lookup table counts must be uint16 values")
        object.__setattr__(self, "counts", counts)
        object.__setattr__(self, "celsius", celsius)

    @classmethod
    def from_measurement(cls, raw: np.ndarray, celsius: np.ndarray, *, source: str,
                         derived_from: dict[str, Any] | None = None) -> LookupTableModel:
        """Build the table from one frame and the vendor's temperatures for it; refuses when the
        vendor gave two temperatures for one count (then a table would misstate some pixels)."""
        raw = np.asarray(raw, dtype=np.uint16).ravel()
        temp = np.asarray(celsius, dtype=np.float64).ravel()
        if raw.shape != temp.shape:
            raise ValueError(f"temperature image has {temp.size} pixels, the frame {raw.size}")
        order = np.argsort(raw, kind="stable")
        counts, first = np.unique(raw[order], return_index=True)
        per_count = temp[order]
        lo = np.minimum.reduceat(per_count, first)
        hi = np.maximum.reduceat(per_count, first)
        if not np.all(np.isfinite(per_count)):
            raise TemperatureUnavailable(f"{source} returned non-finite temperatures")
        if np.any(hi != lo):
            worst = int(counts[np.argmax(hi - lo)])
            raise TemperatureUnavailable(
                f"{source} gave different temperatures for one count (count {worst}: {float(np.max(hi - lo)):.4g} C "
                "apart): not a per-count curve, so thermcap stores no table")
        return cls(tuple(counts.tolist()), tuple(lo.tolist()), source, derived_from)

    def merged(self, other: LookupTableModel) -> LookupTableModel | None:
        """This table and ``other`` as one, or None where they disagree on a shared count."""
        if self.source != other.source or self.derived_from != other.derived_from:
            return None
        table = dict(zip(self.counts, self.celsius, strict=True))
        for c, t in zip(other.counts, other.celsius, strict=True):
            if table.setdefault(c, t) != t:
                return None
        counts = sorted(table)
        return LookupTableModel(tuple(counts), tuple(table[c] for c in counts), self.source, self.derived_from,
                                self.bit_depth)

    @functools.cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.counts, dtype=np.int64), np.asarray(self.celsius, dtype=np.float64)

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        raw = np.asarray(raw)
        keys, values = self._arrays
        idx = np.clip(np.searchsorted(keys, raw.astype(np.int64)), 0, len(keys) - 1)
        missing = keys[idx] != raw
        if np.any(missing):
            raise TemperatureUnavailable(
                f"count {int(raw[missing].flat[0])} is not in the {self.source or 'vendor'} table "
                f"({len(keys)} counts measured at import)")
        return values[idx]

    def summary(self) -> dict[str, Any]:
        """The table's identity without its values: what each per-frame sidecar carries (the full
        table is in the session metadata, once per segment)."""
        digest = hashlib.sha256(json.dumps([self.counts, self.celsius]).encode()).hexdigest()
        return {"kind": self.kind, "source": self.source, "entries": len(self.counts), "table_sha256": digest,
                "derived_from": self.derived_from, "table": "in the session metadata (radiometric_model)"}

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "counts": list(self.counts), "celsius": list(self.celsius), "source": self.source,
                "derived_from": self.derived_from, "bit_depth": self.bit_depth}

