"""Radiometric models: raw counts <-> temperature, carried as data in every session.

A model is a small frozen dataclass with a ``kind`` and JSON-safe parameters, so a session's
metadata fully describes how to turn its counts into temperatures years later, without the code
path that recorded it. ``model_from_dict`` rebuilds a model from that JSON; importers register
further kinds (FLIR Planck, DJI) with ``register_model``.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass, fields
from itertools import pairwise
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np

from recorder.icd.names import BIT_DEPTH, MAX_COUNT
from recorder.registry import Registry

T = TypeVar("T", bound=type)
__all__ = [
    "DEFAULT_MODEL",
    "DjiModel",
    "FlirPlanckModel",
    "LinearModel",
    "LookupTableModel",
    "RadiometricModel",
    "ScaledKelvinModel",
    "TemperatureUnavailable",
    "TerraRefPlanckModel",
    "describe_model",
    "model_from_dict",
    "register_model",
]


@runtime_checkable
class RadiometricModel(Protocol):
    kind: ClassVar[str]

    def to_celsius(self, raw: np.ndarray) -> np.ndarray: ...

    def to_dict(self) -> dict[str, Any]: ...


_MODELS: Registry[Any] = Registry("radiometric model kind", lambda kind, known: ValueError(
    f"unknown radiometric model kind {kind!r}; known: {known}"))


def register_model(cls: T) -> T:
    """Class decorator: make a model kind rebuildable from session metadata."""
    _MODELS.register(cls.kind, cls)  # type: ignore[attr-defined]
    return cls


def model_from_dict(data: dict[str, Any]) -> RadiometricModel:
    """Rebuild a model from ``to_dict()`` output; unknown kinds and fields are errors, not guesses."""
    if not isinstance(data, dict) or "kind" not in data:
        raise ValueError(f"radiometric model must be an object with a 'kind', got {data!r}")
    kind = data["kind"]
    cls: Any = _MODELS.factory(kind)
    params = {k: v for k, v in data.items() if k not in ("kind", "temperature")}
    known = {f.name for f in fields(cls)}
    unknown = set(params) - known
    if unknown:
        raise ValueError(f"radiometric model {kind!r} has unknown parameters {sorted(unknown)}")
    return cls(**params)


def describe_model(model: RadiometricModel) -> dict[str, Any]:
    """A model as a sidecar, a listing or a per-file report shows it: whole, except a lookup table,
    which shows its identity (source, entries, sha256) instead of thousands of entries."""
    summary = getattr(model, "summary", None)
    return summary() if summary is not None else model.to_dict()


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
assert DEFAULT_MODEL.max_count == MAX_COUNT


def _atmospheric_tau(distance_m: float, h2o: float, alpha1: float, alpha2: float, beta1: float, beta2: float,
                     x: float) -> float:
    """FLIR's two-band atmospheric transmission over ``distance_m`` for water vapour ``h2o``
    (Thermimage's ``raw2temp``; TERRA-REF's pipeline uses the same, with its own h2o rounding)."""
    d = np.sqrt(distance_m / 2)
    return (x * np.exp(-d * (alpha1 + beta1 * np.sqrt(h2o)))
            + (1 - x) * np.exp(-d * (alpha2 + beta2 * np.sqrt(h2o))))


def _planck_raw(r1: float, r2: float, b: float, f: float, o: float, temp_c: float) -> float:
    """Raw counts a blackbody at ``temp_c`` would give (FLIR's Planck curve)."""
    return r1 / (r2 * (np.exp(b / (temp_c + 273.15)) - f)) - o


@register_model
@dataclass(frozen=True)
class FlirPlanckModel:
    """FLIR's Planck model with emissivity, reflected and atmospheric temperature, atmospheric
    transmission from distance and humidity, and an IR window: Thermimage's ``raw2temp``, with the
    file's own CameraInfo constants (formats.md 3.3)."""

    kind: ClassVar[str] = "flir_planck"
    planck_r1: float
    planck_b: float
    planck_f: float
    planck_o: float
    planck_r2: float
    emissivity: float = 1.0
    object_distance_m: float = 1.0
    reflected_temp_c: float = 20.0
    atmospheric_temp_c: float = 20.0
    ir_window_temp_c: float = 20.0
    ir_window_transmission: float = 1.0
    relative_humidity_pct: float = 50.0
    alpha1: float = 0.006569
    alpha2: float = 0.01262
    beta1: float = -0.002276
    beta2: float = -0.00667
    trans_x: float = 1.9
    bit_depth: int = 16

    def transmission(self) -> float:
        ta = self.atmospheric_temp_c
        h2o = (self.relative_humidity_pct / 100) * np.exp(1.5587 + 0.06939 * ta - 0.00027816 * ta**2
                                                           + 0.00000068455 * ta**3)
        return float(_atmospheric_tau(self.object_distance_m, h2o, self.alpha1, self.alpha2, self.beta1, self.beta2,
                                      self.trans_x))

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        e, irt = self.emissivity, self.ir_window_transmission
        tau = self.transmission()
        p = lambda t: _planck_raw(self.planck_r1, self.planck_r2, self.planck_b, self.planck_f, self.planck_o, t)  # noqa: E731
        raw_refl = p(self.reflected_temp_c)
        raw_atm = p(self.atmospheric_temp_c)
        raw_win = p(self.ir_window_temp_c)
        offset = ((1 - e) / e * raw_refl + (1 - tau) / e / tau * raw_atm + (1 - irt) / e / tau / irt * raw_win
                  + (1 - tau) / e / tau / irt / tau * raw_atm)
        raw_obj = np.asarray(raw, dtype=np.float64) / e / tau / irt / tau - offset
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = self.planck_r1 / (self.planck_r2 * (raw_obj + self.planck_o))
            return self.planck_b / np.log(ratio + self.planck_f) - 273.15

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **asdict(self)}


@register_model
@dataclass(frozen=True)
class TerraRefPlanckModel:
    """TERRA-REF gantry FLIR A615 (``FlirRawToTemperature``): Planck with R, B, F, J0, J1.

    ``variant="pipeline"`` (the default) reproduces the TERRA-REF pipeline exactly, including its
    forward-model step (``raw*E*tau + ...`` where a physical inversion divides), because that is
    what every published TERRA-REF temperature product used; ``"physical"`` inverts the
    measurement equation properly (about +0.6 C on the sample). ``"plain"`` is E = tau = 1."""

    kind: ClassVar[str] = "terraref_planck"
    r: float
    b: float
    f: float
    j0: float
    j1: float
    alpha1: float = 0.006569
    alpha2: float = 0.01262
    beta1: float = -0.002276
    beta2: float = -0.00667
    x: float = 1.9
    humidity: float = 0.1
    atm_temp_c: float = 22.0
    distance_m: float = 2.5
    emissivity: float = 0.98
    variant: str = "pipeline"
    bit_depth: int = 16

    def __post_init__(self) -> None:
        if self.variant not in ("pipeline", "physical", "plain"):
            raise ValueError(f"variant must be pipeline, physical or plain, got {self.variant!r}")

    def _p(self, t_k: float) -> float:
        return self.r * self.j1 / (np.exp(self.b / t_k) - self.f) + self.j0

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        raw = np.asarray(raw, dtype=np.float64)
        if self.variant == "plain":
            corr = raw
        else:
            t, h = self.atm_temp_c, self.humidity
            h2o = h * np.exp(1.56 + 0.0694 * t - 0.000278 * t**2 + 0.000000685 * t**3)  # the pipeline's rounding
            tau = _atmospheric_tau(self.distance_m, h2o, self.alpha1, self.alpha2, self.beta1, self.beta2, self.x)
            p_atm = self._p(t + 273.15)
            e = self.emissivity
            if self.variant == "pipeline":  # as implemented in FlirRawToTemperature.m / Get_FLIR.py
                corr = raw * e * tau + (1 - tau) * p_atm + (1 - e) * tau * p_atm
            else:
                corr = (raw - (1 - tau) * p_atm - (1 - e) * tau * p_atm) / (e * tau)
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.b / np.log(self.r / (corr - self.j0) * self.j1 + self.f) - 273.15

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **asdict(self)}


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


class TemperatureUnavailable(ValueError):
    """The counts are kept bit-exact, but no honest temperature can be computed here."""


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
