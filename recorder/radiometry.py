"""Radiometric models: raw counts <-> temperature, carried as data in every session.

A model is a small frozen dataclass with a ``kind`` and JSON-safe parameters, so a session's
metadata fully describes how to turn its counts into temperatures years later, without the code
path that recorded it. ``model_from_dict`` rebuilds a model from that JSON; importers register
further kinds (FLIR Planck, DJI) with ``register_model``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from .icd import BIT_DEPTH, MAX_COUNT

__all__ = [
    "RadiometricModel",
    "LinearModel",
    "register_model",
    "model_from_dict",
    "DEFAULT_MODEL",
]


@runtime_checkable
class RadiometricModel(Protocol):
    kind: ClassVar[str]

    def to_celsius(self, raw: np.ndarray) -> np.ndarray: ...

    def to_dict(self) -> dict[str, Any]: ...


_MODELS: dict[str, type] = {}


def register_model(cls: type) -> type:
    """Class decorator: make a model kind rebuildable from session metadata."""
    _MODELS[cls.kind] = cls
    return cls


def model_from_dict(data: dict[str, Any]) -> RadiometricModel:
    """Rebuild a model from ``to_dict()`` output; unknown kinds and fields are errors, not guesses."""
    if not isinstance(data, dict) or "kind" not in data:
        raise ValueError(f"radiometric model must be an object with a 'kind', got {data!r}")
    kind = data["kind"]
    try:
        cls = _MODELS[kind]
    except KeyError:
        raise ValueError(f"unknown radiometric model kind {kind!r}; known: {sorted(_MODELS)}") from None
    params = {k: v for k, v in data.items() if k != "kind"}
    known = {f.name for f in fields(cls)}
    unknown = set(params) - known
    if unknown:
        raise ValueError(f"radiometric model {kind!r} has unknown parameters {sorted(unknown)}")
    return cls(**params)


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
    def from_range(cls, temp_min_c: float, temp_max_c: float, bit_depth: int = BIT_DEPTH) -> "LinearModel":
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
assert DEFAULT_MODEL.max_count == MAX_COUNT
