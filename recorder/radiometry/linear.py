"""Linear and scaled-Kelvin models: the ICD's ``T = counts * 0.036 - 40`` and cameras that output
centikelvin."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.icd.names import BIT_DEPTH
from thermcap.recorder.radiometry.base import register_model

__all__ = ["DEFAULT_MODEL", "LinearModel", "ScaledKelvinModel"]


@register_model
@dataclass(frozen=True)
class LinearModel:
    """ICD 3.1/3.3: ``T_celsius = counts * scale + offset``.

    The default is the ICD's FLIR Boson calibration (0.036 C/count, -40 C). The inverse mapping
    rounds to the nearest count (the ICD's sample code truncates, which biases every temperature
    down by half a count) and clamps to the valid range [0, 2**bit_depth - 1].
    """

    kind: ClassVar[str] = "linear"
    scale_c_per_count: float = 0.036
    offset_c: float = -40.0
    bit_depth: int = BIT_DEPTH

    def __post_init__(self) -> None:
        if not self.scale_c_per_count > 0:
            raise ValueError(f"scale_c_per_count must be > 0, got {self.scale_c_per_count}")
        if not 1 <= self.bit_depth <= 16:
            raise ValueError(f"bit_depth must be 1..16, got {self.bit_depth}")

    @classmethod
    def from_range(cls, temp_min_c: float, temp_max_c: float, bit_depth: int = BIT_DEPTH) -> LinearModel:
        """ICD 3.3 user-defined range: the full count range spans [temp_min_c, temp_max_c]."""
        if not temp_max_c > temp_min_c:
            raise ValueError(f"temp_max_c ({temp_max_c}) must exceed temp_min_c ({temp_min_c})")
        return cls((temp_max_c - temp_min_c) / ((1 << bit_depth) - 1), float(temp_min_c), bit_depth)

    @property
    def max_count(self) -> int:
        return (1 << self.bit_depth) - 1

    @property
    def temp_min_c(self) -> float:
        return self.offset_c

    @property
    def temp_max_c(self) -> float:
        return self.max_count * self.scale_c_per_count + self.offset_c

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        return np.asarray(raw, dtype=np.float64) * self.scale_c_per_count + self.offset_c

    def from_celsius(self, temp_c: np.ndarray | float) -> np.ndarray:
        counts = np.rint((np.asarray(temp_c, dtype=np.float64) - self.offset_c) / self.scale_c_per_count)
        return np.clip(counts, 0, self.max_count).astype(np.uint16)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **asdict(self)}



DEFAULT_MODEL = LinearModel()



@register_model
@dataclass(frozen=True)
class ScaledKelvinModel:
    """Counts are kelvin times ``counts_per_kelvin`` (TERRA-REF calibrated data: 0.1 K, 10 per K;
    FLIR/flirpy radiometric TIFF: 0.04 K, 25 per K)."""

    kind: ClassVar[str] = "scaled_kelvin"
    counts_per_kelvin: float = 10.0
    bit_depth: int = 16

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        return np.asarray(raw, dtype=np.float64) / self.counts_per_kelvin - 273.15

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **asdict(self)}

