"""A seeded thermal scene simulator that also plays the radar side of ICD section 8.

The scene: cold sky over warmer textured ground, warm targets moving across it (a drone motor
at 40-50 C, a vehicle, a person), NETD temporal noise, column fixed-pattern noise and a few
dead/hot pixels (listed in the bad-pixel map). An optional thermal crossover fades every
target's contrast against its local background to nothing and back, as at dawn or dusk, so the
contrast grade falls below 0.3.

The radar side: at ``cue_period_s`` the radar cues the drone; the turret state machine runs
cue -> slew -> spiral search -> lock -> handoff -> idle and fills ``slew_to_cue``. By default the
camera image stays scene-fixed (the turret motion is in the metadata only), which keeps ground
truth simple and exact. ``view="turret"`` pans the picture with the turret's pan angle over a
360-degree panorama (``pan_px_per_deg`` pixels a degree); ``view="patrol"`` sweeps it back and
forth at ``patrol_deg_s`` whether cued or not: the moving scenes a temporal codec must be measured
on. The targets keep their own motion in the picture; the tilt does not move it.

Noise, besides NETD: ``fpn_mk`` column fixed-pattern noise and ``pixel_fpn_mk`` per-pixel
fixed-pattern noise, both tied to the sensor (they stay put while the scene pans), and
``drift_mk`` a global 1/f drift (eight sinusoids from 0.01 to 1 Hz with amplitudes in 1/sqrt(f)),
as an uncooled core drifts between flat-field corrections.

What a camera on a vehicle or a mast adds, for the temporal codec's measurements: ``shake_px``
moves the picture (scene and targets, not the sensor's pattern) by a random sub-pixel offset
each frame, up to that many pixels on each axis (bilinear, as optics blur a shake), which no
whole-pixel motion search can follow; ``gain_every_s`` changes the core's gain (AGC) at that
period to a new value within ``1 +- gain_step``, scaling every count's distance from the
scene's mean level (the sensor's pattern and the noise with it, as a gain after the detector
does): a frame-wide step no prediction from earlier frames foresees; ``row_runs`` makes that share
of the pixels repeat their left neighbour's value, in runs along the rows that change every
frame, as a real FLIR CSQ sequence holds them (44-62 % of its pixels; a cause inside the camera
no document names).

For the ICD section 5 quality report's proof: ``blackbody_c`` fills the view with a uniform
blackbody at that temperature (no scene, no targets); ``shutter_every_s`` closes the shutter for
``shutter_frames`` frames at that period (a uniform field at ``shutter_c``, marked
``capture.shutter_closed`` in the sidecar), and with ``nuc_step_counts`` the flat-field
correction each closing makes leaves the picture a new frame-wide offset, within that many
counts of the first (the step an uncooled core's raw output takes at each NUC);
``drift_c_per_h`` adds a linear response drift. With the NETD, the pattern noise and the bad
pixels, these are the truths the report must recover.

Determinism: frame ``i`` depends only on the seed and ``i`` (timestamps aside): two runs with
the same seed give the same pixels, bit for bit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, Pacer, SensorInfo
from thermcap.recorder.capture.sources.registry import CameraSettings, SourceKind, register_source
from thermcap.recorder.icd.names import MAX_COUNT, iso_utc
from thermcap.recorder.icd.quality import contrast_metrics, frame_analysis
from thermcap.recorder.icd.topics import GROUND_TRUTH_SCHEMA, RADAR_CUE_SCHEMA, TOPIC_GROUND_TRUTH, TOPIC_RADAR_CUE
from thermcap.recorder.radiometry import LinearModel

__all__ = ["SimSource", "SimTarget", "SlewToCue"]


@dataclass
class SimTarget:
    target_id: str
    classification: str
    temp_c: float  # temperature at full contrast
    size: tuple[int, int]  # (w, h) px at 640 wide
    pos: tuple[float, float]  # initial top-left as a fraction of (W, H)
    vel: tuple[float, float]  # px/s at 640 wide
    region: str  # "sky" or "ground": where it bounces
    delta_k: float | None = None  # if set: this many K above its local background, not temp_c
    scale_size: bool = True  # sizes scale with the frame width (off: exact pixel sizes)


DEFAULT_TARGETS = (
    SimTarget("TGT001", "drone_motor", 46.0, (6, 6), (0.20, 0.15), (48.0, 9.0), "sky"),
    SimTarget("TGT002", "vehicle", 38.0, (40, 18), (0.55, 0.70), (-30.0, 0.0), "ground"),
    SimTarget("TGT003", "person", 33.0, (6, 16), (0.30, 0.62), (7.0, 2.0), "ground"),
)


class SlewToCue:
    """The turret's cue-handling state machine (ICD 4.3.2 / 8.1), advanced once a frame."""

    SLEW_RATE_DEG_S = 40.0
    SEARCH_S = 1.5
    LOCK_S = 3.0
    HANDOFF_S = 0.5

    def __init__(self, rng: np.random.Generator, cue_period_s: float, first_cue_s: float = 2.0):
        self.rng = rng
        self.cue_period_s = cue_period_s
        self.next_cue_s = first_cue_s
        self.state = "idle"
        self.state_since = 0.0
        self.pan, self.tilt = 0.0, 5.0
        self.cue: dict[str, Any] | None = None
        self.cue_count = 0

    def step(self, t: float, ts_ns: int, target_visible: bool) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        cues: list[dict[str, Any]] = []
        if self.state == "idle" and self.cue_period_s > 0 and t >= self.next_cue_s:
            self.cue_count += 1
            az = float(self.rng.uniform(-60, 60))
            el = float(self.rng.uniform(5, 25))
            rng_m = float(self.rng.uniform(400, 1500))
            lat0, lon0 = 37.7749, -122.4194
            north = rng_m * math.cos(math.radians(el)) * math.cos(math.radians(az))
            east = rng_m * math.cos(math.radians(el)) * math.sin(math.radians(az))
            self.cue = {
                "timestamp": iso_utc(ts_ns),
                "target_id": f"TRK{self.cue_count:03d}",
                "latitude": lat0 + north / 111_320.0,
                "longitude": lon0 + east / (111_320.0 * math.cos(math.radians(lat0))),
                "altitude_m": rng_m * math.sin(math.radians(el)),
                "azimuth_deg": az,
                "elevation_deg": el,
                "range_m": rng_m,
                "uncertainty_m": 10.0,
            }
            cues.append(dict(self.cue))
            self.next_cue_s = t + self.cue_period_s
            self._enter("slew", t)
        dt_state = t - self.state_since
        if self.state == "slew" and self.cue:
            max_step = self.SLEW_RATE_DEG_S / 60.0
            dp = self.cue["azimuth_deg"] + 0.3 - self.pan
            dtl = self.cue["elevation_deg"] + 0.3 - self.tilt
            dist = math.hypot(dp, dtl)
            if dist <= max_step:
                self.pan, self.tilt = self.cue["azimuth_deg"] + 0.3, self.cue["elevation_deg"] + 0.3
                self._enter("search", t)
            else:
                self.pan += dp / dist * max_step
                self.tilt += dtl / dist * max_step
        elif self.state == "search" and self.cue:
            # Archimedean spiral within +-2 deg of the cue.
            theta = dt_state * 4 * math.pi
            r = min(2.0, 2.0 * dt_state / self.SEARCH_S)
            self.pan = self.cue["azimuth_deg"] + r * math.cos(theta)
            self.tilt = self.cue["elevation_deg"] + r * math.sin(theta)
            if dt_state >= self.SEARCH_S and target_visible:
                self._enter("lock", t)
        elif self.state == "lock" and self.cue:
            self.pan = self.cue["azimuth_deg"] + 0.05 * math.sin(t)
            self.tilt = self.cue["elevation_deg"] + 0.05 * math.cos(t)
            if dt_state >= self.LOCK_S:
                self._enter("handoff", t)
        elif self.state == "handoff" and dt_state >= self.HANDOFF_S:
            self._enter("idle", t)
            self.cue = None
        if self.state in ("slew", "search") and self.cue and cues == [] and int(t) != int(t - 1 / 60.0):
            cues.append({**self.cue, "timestamp": iso_utc(ts_ns)})  # radar keeps reporting, 1 Hz
        cue = self.cue
        block = {
            "slew_to_cue_active": self.state in ("slew", "search", "lock"),
            "radar_cue_received": cue is not None,
            "radar_azimuth_deg": cue["azimuth_deg"] if cue else None,
            "radar_elevation_deg": cue["elevation_deg"] if cue else None,
            "radar_range_m": cue["range_m"] if cue else None,
            "turret_pan_deg": round(self.pan, 4),
            "turret_tilt_deg": round(self.tilt, 4),
            "search_pattern_active": self.state == "search",
            "state": self.state,
        }
        return block, cues

    def _enter(self, state: str, t: float) -> None:
        self.state = state
        self.state_since = t


class SimSource(FrameSource):
    """``thermcap record --source sim``: see the module docstring for what it simulates."""

    name = "sim"
    extra_topics: ClassVar[dict[str, dict[str, Any]]] = {TOPIC_RADAR_CUE: RADAR_CUE_SCHEMA,
                                                         TOPIC_GROUND_TRUTH: GROUND_TRUTH_SCHEMA}

    def __init__(
        self,
        *,
        width: int = 640,
        height: int = 512,
        fps: float = 60.0,
        seed: int = 0,
        frames: int | None = None,
        duration_s: float | None = None,
        paced: bool = True,
        netd_mk: float = 50.0,
        fpn_mk: float = 20.0,
        bad_pixels: int = 12,
        crossover: bool = False,
        crossover_center_s: float | None = None,
        crossover_half_width_s: float | None = None,
        cue_period_s: float = 20.0,
        first_cue_s: float = 2.0,
        targets: tuple[SimTarget, ...] = DEFAULT_TARGETS,
        start_time_ns: int | None = None,
        sensor_id: str = "SIM640",
        view: str = "fixed",
        pan_px_per_deg: float = 12.8,
        patrol_deg_s: float = 10.0,
        pixel_fpn_mk: float = 0.0,
        drift_mk: float = 0.0,
        blackbody_c: float | None = None,
        shutter_every_s: float | None = None,
        shutter_frames: int = 4,
        shutter_c: float = 25.0,
        nuc_step_counts: float = 0.0,
        drift_c_per_h: float = 0.0,
        shake_px: float = 0.0,
        gain_every_s: float | None = None,
        gain_step: float = 0.05,
        row_runs: float = 0.0,
    ) -> None:
        if width < 16 or height < 16:
            raise ValueError(f"simulator frames must be at least 16x16, got {width}x{height}")
        if view not in ("fixed", "turret", "patrol"):
            raise ValueError(f"view must be fixed, turret or patrol, got {view!r}")
        if not 0.0 <= shake_px <= 8.0:
            raise ValueError(f"shake_px must be between 0 and 8 pixels, got {shake_px}")
        if gain_every_s is not None and (gain_every_s <= 0 or not 0.0 <= gain_step < 1.0):
            raise ValueError(f"gain steps need gain_every_s > 0 and 0 <= gain_step < 1, "
                             f"got {gain_every_s}, {gain_step}")
        if not 0.0 <= nuc_step_counts <= 4096 or (nuc_step_counts and not shutter_every_s):
            raise ValueError(f"nuc_step_counts is 0..4096 counts and needs shutter_every_s, got {nuc_step_counts}")
        if not 0.0 <= row_runs < 1.0:
            raise ValueError(f"row_runs is a share of the pixels, 0 <= row_runs < 1, got {row_runs}")
        self.shake_px, self.gain_every_s, self.gain_step = shake_px, gain_every_s, gain_step
        self.row_runs, self.nuc_step_counts = row_runs, nuc_step_counts
        self.view, self.pan_px_per_deg, self.patrol_deg_s = view, pan_px_per_deg, patrol_deg_s
        self.blackbody_c, self.shutter_every_s, self.shutter_frames = blackbody_c, shutter_every_s, shutter_frames
        self.shutter_c, self.drift_c_per_h = shutter_c, drift_c_per_h
        if blackbody_c is not None:
            targets = ()
        self._pan_deg = 0.0
        self.width, self.height, self.fps = width, height, fps
        self.model: LinearModel = LinearModel()
        self.sensor = SensorInfo(model="thermcap simulator (Boson-like)", sensor_id=sensor_id,
                                 serial_number=f"SIM-{seed}", width=width, height=height,
                                 netd_mk=netd_mk, frame_rate_hz=fps)
        if frames is None and duration_s is not None:
            frames = round(duration_s * fps)
        self.n_frames = frames
        self.paced = paced
        # Paced, it plays a live camera (stamped when each frame is released, late frames counted);
        # unpaced, a recording read as fast as it can be written (stamped at its position).
        self.can_wait = not paced
        self.time_basis = "capture" if paced else "stream"
        self.seed = seed
        self.netd_mk = netd_mk
        self.targets = targets
        self.crossover = crossover
        total_s = (frames / fps) if frames else 60.0
        self.crossover_center_s = crossover_center_s if crossover_center_s is not None else total_s / 2
        self.crossover_half_width_s = crossover_half_width_s if crossover_half_width_s is not None else total_s / 4
        self.cue_period_s = cue_period_s
        self.first_cue_s = first_cue_s
        self.start_time_ns = start_time_ns
        self._scale = width / 640.0
        rng = np.random.default_rng(seed)
        self._rng_noise = np.random.default_rng([seed, 1])
        self._rng_radar = np.random.default_rng([seed, 2])
        self._horizon = int(height * 0.45)
        self._background_c = self._make_background(rng)
        sigma_counts = netd_mk / 1000.0 / self.model.scale_c_per_count
        fpn = rng.normal(0.0, fpn_mk / 1000.0 / self.model.scale_c_per_count, size=(1, width)).astype(np.float32)
        self._background_counts = (
            (self._background_c - self.model.offset_c) / self.model.scale_c_per_count + fpn
        ).astype(np.float32)
        self._fpn_counts = fpn
        if pixel_fpn_mk:
            self._fpn_counts = (fpn + rng.normal(0.0, pixel_fpn_mk / 1000.0 / self.model.scale_c_per_count,
                                                 size=(height, width))).astype(np.float32)
            self._background_counts += self._fpn_counts - fpn
        if view != "fixed":  # a 360-degree panorama the view pans over (wrapping), in counts without the FPN
            span = max(width, round(360 * pan_px_per_deg))
            self._panorama_counts = ((self._make_background(rng, span) - self.model.offset_c)
                                     / self.model.scale_c_per_count).astype(np.float32)
        rng_drift = np.random.default_rng([seed, 3])
        freqs = np.logspace(-2, 0, 8)
        amps = 1 / np.sqrt(freqs)
        amps *= (drift_mk / 1000.0 / self.model.scale_c_per_count) / max(float(np.sqrt((amps ** 2).sum() / 2)), 1e-9)
        self._drift = (freqs, amps, rng_drift.uniform(0, 2 * np.pi, 8)) if drift_mk else None
        n = width * height
        self._noise_pool = (rng.standard_normal(n * 3, dtype=np.float32) * np.float32(sigma_counts))
        # Dead (0) and hot (max) pixels, away from the borders.
        self.bad_pixel_map: np.ndarray = np.zeros((height, width), dtype=bool)
        ys = rng.integers(2, height - 2, size=bad_pixels)
        xs = rng.integers(2, width - 2, size=bad_pixels)
        self.bad_pixel_map[ys, xs] = True
        self._bad_values = np.where(np.arange(bad_pixels) % 2 == 0, 0, MAX_COUNT).astype(np.uint16)
        self._bad_ys, self._bad_xs = ys, xs

    def describe(self) -> dict[str, Any]:
        out = {"source": "sim", "seed": self.seed, "crossover": self.crossover, "netd_mk": self.netd_mk,
               "cue_period_s": self.cue_period_s, "view": self.view}
        if self.blackbody_c is not None:
            out["blackbody_c"] = self.blackbody_c
        if self.shutter_every_s:
            out.update(shutter_every_s=self.shutter_every_s, shutter_c=self.shutter_c)
        if self.nuc_step_counts:
            out["nuc_step_counts"] = self.nuc_step_counts
        if self.shake_px:
            out["shake_px"] = self.shake_px
        if self.gain_every_s:
            out.update(gain_every_s=self.gain_every_s, gain_step=self.gain_step)
        if self.row_runs:
            out["row_runs"] = self.row_runs
        return out

    def shake(self, index: int) -> tuple[float, float]:
        """Frame ``index``'s sub-pixel shake (dx, dy) in pixels: a function of the seed and the index."""
        if not self.shake_px:
            return 0.0, 0.0
        dx, dy = np.random.default_rng([self.seed, 5, index]).uniform(-self.shake_px, self.shake_px, 2)
        return float(dx), float(dy)

    def gain(self, index: int) -> float:
        """The core's gain at frame ``index``: 1 until the first step, then a new value within
        ``1 +- gain_step`` at each step, a function of the seed and the step's number."""
        return 1.0 + self._held_step(index, self.gain_every_s, self.gain_step, 6)

    def nuc_offset(self, index: int) -> float:
        """The frame-wide offset (counts) the last flat-field correction before frame ``index``
        left: 0 until the first closing, then a new value within ``nuc_step_counts`` at each,
        a function of the seed and the closing's number."""
        return self._held_step(index, self.shutter_every_s, self.nuc_step_counts, 8)

    def shutter_closed(self, index: int) -> bool:
        if not self.shutter_every_s:
            return False
        return index % self._period(self.shutter_every_s) < self.shutter_frames

    def _period(self, seconds: float) -> int:
        return max(1, round(seconds * self.fps))

    def _held_step(self, index: int, every_s: float | None, amplitude: float, stream: int) -> float:
        """A value held for ``every_s`` seconds at a time: 0 in the first period, then a new one
        within ``+-amplitude`` each period, drawn from the seed's ``stream`` and the period's number."""
        if not every_s or not amplitude:
            return 0.0
        k = index // self._period(every_s)
        if k == 0:
            return 0.0
        return float(np.random.default_rng([self.seed, stream, k]).uniform(-amplitude, amplitude))

    # -- scene ------------------------------------------------------------------------------
    def _make_background(self, rng: np.random.Generator, width: int | None = None) -> np.ndarray:
        h, w, hz = self.height, width or self.width, self._horizon
        y = np.arange(h, dtype=np.float32)[:, None]
        sky = -18.0 + 20.0 * (y / max(hz, 1))  # -18 C at the top to +2 C at the horizon
        ground = 14.0 + 6.0 * ((y - hz) / max(h - hz, 1))
        bg = np.where(y < hz, sky, ground) * np.ones((1, w), np.float32)
        # Smooth ground texture: coarse noise, upsampled.
        coarse = rng.normal(0.0, 1.5, size=(h // 16 + 2, w // 16 + 2)).astype(np.float32)
        tex = np.kron(coarse, np.ones((16, 16), np.float32))[:h, :w]
        k = np.ones(9, np.float32) / 9
        if width:  # a panorama: the texture wraps around, so 360 degrees meet without a seam
            from scipy.ndimage import uniform_filter1d

            tex = uniform_filter1d(tex, 9, axis=1, mode="wrap")
        else:
            tex = np.apply_along_axis(lambda r: np.convolve(r, k, mode="same"), 1, tex)
        tex = np.apply_along_axis(lambda c: np.convolve(c, k, mode="same"), 0, tex)
        bg[hz:] += tex[hz:]
        return bg.astype(np.float32)

    def crossover_factor(self, t: float) -> float:
        """1 = full contrast. Within ``crossover_half_width_s`` of the centre it ramps down to 0,
        stays at 0 for the middle third (targets at their background's temperature), and recovers."""
        if not self.crossover:
            return 1.0
        hw = self.crossover_half_width_s
        d = abs(t - self.crossover_center_s)
        return float(np.clip((d - hw / 3) / (hw * 2 / 3), 0.0, 1.0))

    def view_offset_px(self, t: float) -> int:
        """Where the view's left edge is on the panorama: the turret's pan, or the patrol sweep
        (a triangle wave over +-30 degrees)."""
        if self.view == "patrol":
            period = 4 * 30.0 / self.patrol_deg_s
            phase = (t % period) / period
            pan = 30.0 * (4 * phase - 1 if phase < 0.5 else 3 - 4 * phase)
        else:
            pan = self._pan_deg
        return round(pan * self.pan_px_per_deg)

    def _target_box(self, tgt: SimTarget, t: float) -> tuple[int, int, int, int]:
        s = self._scale if tgt.scale_size else 1.0
        tw, th = max(2, round(tgt.size[0] * s)), max(2, round(tgt.size[1] * s))
        if tgt.region == "sky":
            y_lo, y_hi = 0, self._horizon - th - 2
        else:
            y_lo, y_hi = self._horizon + 2, self.height - th
        x_lo, x_hi = 0, self.width - tw

        def bounce(p0: float, v: float, lo: int, hi: int) -> int:
            span = max(hi - lo, 1)
            p = (p0 - lo + v * t) % (2 * span)
            return int(lo + (p if p <= span else 2 * span - p))

        x = bounce(tgt.pos[0] * self.width, tgt.vel[0] * s, x_lo, x_hi)
        y = bounce(min(max(tgt.pos[1] * self.height, y_lo), y_hi), tgt.vel[1] * s, y_lo, y_hi)
        return x, y, tw, th

    def render(self, index: int) -> tuple[np.ndarray, list[dict[str, Any]], dict[str, Any], np.ndarray]:
        """Frame ``index``: (counts, ground-truth targets, thermal_analysis, noiseless target temps)."""
        t = index / self.fps
        f = self.crossover_factor(t)
        uniform_c = self.shutter_c if self.shutter_closed(index) else self.blackbody_c
        if uniform_c is not None:  # a uniform field: the shutter, or a blackbody filling the view
            level = (uniform_c - self.model.offset_c) / self.model.scale_c_per_count
            counts_f = np.full((self.height, self.width), level, np.float32) + self._fpn_counts
        elif self.view == "fixed":
            counts_f = self._background_counts.copy()
        else:
            counts_f = np.take(self._panorama_counts, self.view_offset_px(t) + np.arange(self.width), axis=1,
                               mode="wrap") + self._fpn_counts
        if self._drift is not None:
            fr, amp, ph = self._drift
            counts_f += np.float32((amp * np.sin(2 * np.pi * fr * t + ph)).sum())
        if self.drift_c_per_h:
            counts_f += np.float32(self.drift_c_per_h * t / 3600.0 / self.model.scale_c_per_count)
        truths = []
        model = self.model
        for tgt in (self.targets if uniform_c is None else ()):
            x, y, tw, th = self._target_box(tgt, t)
            local_bg = float(self._background_c[y:y + th, x:x + tw].mean())
            full = tgt.temp_c if tgt.delta_k is None else local_bg + tgt.delta_k
            temp = local_bg + (full - local_bg) * f
            yy, xx = np.ogrid[:th, :tw]
            ell = ((yy - (th - 1) / 2) / (th / 2)) ** 2 + ((xx - (tw - 1) / 2) / (tw / 2)) ** 2 <= 1.0
            # A hot core: the centre 2 K above the rim at full contrast (never below the background).
            core = 1.0 - np.clip(((yy - (th - 1) / 2) / (th / 2)) ** 2 + ((xx - (tw - 1) / 2) / (tw / 2)) ** 2, 0, 1)
            hot = max(0.0, min(1.0, (temp - local_bg) / 2.0))
            temps = (temp - hot * f + 2.0 * hot * f * core).astype(np.float32)
            region = counts_f[y:y + th, x:x + tw]
            region[ell] = ((temps - model.offset_c) / model.scale_c_per_count)[ell]
            truths.append({"target": tgt, "box": (x, y, tw, th), "mask": ell, "temp_c": temp})
        if self.shake_px:  # the picture moves on the sensor; its fixed pattern does not
            from scipy.ndimage import shift

            dx, dy = self.shake(index)
            scene = counts_f - self._fpn_counts
            counts_f = shift(scene, (dy, dx), order=1, mode="nearest", prefilter=False) + self._fpn_counts
        if uniform_c is None and (step := self.nuc_offset(index)):
            counts_f += np.float32(step)
        n = self.width * self.height
        off = int(self._rng_noise.integers(0, self._noise_pool.size - n))
        counts_f += self._noise_pool[off:off + n].reshape(self.height, self.width)
        g = self.gain(index)
        if g != 1.0:  # AGC: every count's distance from the scene's mean level, scaled
            pivot = np.float32(self._background_counts.mean())
            counts_f -= pivot
            counts_f *= np.float32(g)
            counts_f += pivot
        np.rint(counts_f, out=counts_f)
        np.clip(counts_f, 0, MAX_COUNT, out=counts_f)
        frame = counts_f.astype(np.uint16)
        if self.row_runs:  # each repeating pixel takes the value of the last one before it that does not
            repeat = np.random.default_rng([self.seed, 7, index]).random(frame.shape) < self.row_runs
            repeat[:, 0] = False
            cols = np.maximum.accumulate(np.where(repeat, 0, np.arange(self.width)), axis=1)
            frame = np.take_along_axis(frame, cols, axis=1)
        frame[self._bad_ys, self._bad_xs] = self._bad_values
        gt, analysis = self._truth(frame, truths)
        return frame, gt, analysis, counts_f

    def _truth(self, frame: np.ndarray, truths: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """Sidecar targets and ICD 7.1 metrics from the true masks: each target against a ring of
        local background 3..10 px around it (a global background would always include the sky)."""
        model = self.model
        gt = []
        per_target = []
        ring = max(4, round(8 * self._scale))
        for tr in truths:
            x, y, tw, th = tr["box"]
            mask = tr["mask"]
            temps = model.to_celsius(frame[y:y + th, x:x + tw][mask])
            ys, xs = np.nonzero(mask)
            gt.append({
                "target_id": tr["target"].target_id,
                "bbox": [int(x + xs.min()), int(y + ys.min()), int(x + xs.max()), int(y + ys.max())],
                "centroid": [round(float(x + xs.mean()), 2), round(float(y + ys.mean()), 2)],
                "max_temp_c": round(float(temps.max()), 3),
                "mean_temp_c": round(float(temps.mean()), 3),
                "classification": tr["target"].classification,
                "confidence": 1.0,
                "true_temp_c": round(tr["temp_c"], 3),
            })
            y0, y1 = max(0, y - ring), min(self.height, y + th + ring)
            x0, x1 = max(0, x - ring), min(self.width, x + tw + ring)
            crop = model.to_celsius(frame[y0:y1, x0:x1])
            bg_mask = np.ones(crop.shape, bool)
            bg_mask[max(0, y - 2 - y0):y + th + 2 - y0, max(0, x - 2 - x0):x + tw + 2 - x0] = False
            bg_mask &= ~self.bad_pixel_map[y0:y1, x0:x1]
            tgt_mask = np.zeros(crop.shape, bool)
            tgt_mask[y - y0:y - y0 + th, x - x0:x - x0 + tw] = mask
            tgt_mask &= ~self.bad_pixel_map[y0:y1, x0:x1]
            if tgt_mask.any() and bg_mask.any():
                per_target.append(contrast_metrics(crop, tgt_mask, bg_mask))
        return gt, frame_analysis(per_target, source="ground_truth", confidence=1.0)

    # -- the source ---------------------------------------------------------------------------
    def frames(self) -> Iterator[CapturedFrame]:
        start_ns = self.start_time_ns if self.start_time_ns is not None else time.time_ns()
        period_ns = 1e9 / self.fps
        pacer = Pacer(self.fps, self.paced)
        stc = SlewToCue(self._rng_radar, self.cue_period_s, self.first_cue_s)
        index = 0
        while (self.n_frames is None or index < self.n_frames) and not self.stopped:
            released = pacer.wait(index)
            self.frames_late = pacer.late
            # paced: the time the frame was actually produced, late or not; else its stream position
            ts = start_ns + (released - pacer.start) if self.paced else start_ns + round(index * period_ns)
            frame, gt, analysis, _ = self.render(index)
            t = index / self.fps
            drone_visible = any(g["classification"] == "drone_motor" for g in gt) \
                and analysis["thermal_contrast_grade"] >= 0.3
            stc_block, cues = stc.step(t, ts, drone_visible)
            self._pan_deg = stc.pan  # view="turret": the next frame looks where the turret now points
            messages: list[tuple[str, dict[str, Any]]] = [(TOPIC_RADAR_CUE, c) for c in cues]
            messages.append((TOPIC_GROUND_TRUTH, {
                "frame_index": index, "targets": gt, "crossover_factor": round(self.crossover_factor(t), 4),
                "slew_state": stc_block["state"]}))
            yield CapturedFrame(
                index=index, timestamp_ns=ts, pixels=frame, capture_mono_ns=released,
                sidecar={
                    **({"capture": {"shutter_closed": True}} if self.shutter_closed(index) else {}),
                    "thermal_analysis": analysis,
                    "slew_to_cue": stc_block,
                    "targets": [{k: v for k, v in g.items() if k != "true_temp_c"} for g in gt],
                    "environment": {"ambient_temp_c": 18.0, "humidity_percent": 45.0,
                                    "atmospheric_transmission": 0.98, "weather_condition": "clear",
                                    "visibility_m": 10000},
                },
                messages=messages,
            )
            index += 1


def _from_settings(_target: str, s: CameraSettings) -> SimSource:
    return SimSource(width=s.width, height=s.height, fps=s.fps, seed=s.seed, crossover=s.crossover,
                     cue_period_s=s.cue_period_s, paced=True if s.pace is None else s.pace, duration_s=s.duration_s,
                     sensor_id=s.sensor_id or "SIM640")


register_source(SourceKind("sim", "sim", _from_settings, counts_duration=True, paced_by_default=True))
