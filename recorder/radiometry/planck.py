"""Planck models: FLIR's R1/R2/B/F/O with its atmosphere, and TERRA-REF's FLIR calibration."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.radiometry.base import register_model

__all__ = ["FlirPlanckModel", "TerraRefPlanckModel"]


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

