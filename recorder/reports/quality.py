"""The ICD section 5 quality report: each requirement measured from a session, against its limit.

One pass over the frames (bounded memory: a few per-pixel float64 sums). Frames that see a
uniform field are the reference: every frame of a blackbody session (``--blackbody`` or the
simulator's ``blackbody_c``), or the shutter frames (``capture.shutter_closed``). From them:

- **NETD** (ICD 5.2): per pixel, the standard deviation of the difference of consecutive flat
  frames over sqrt(2), the median over good pixels, times the model's °C per count at that
  level. Differences remove the fixed pattern and slow drift, which the ICD's one-image std
  would count as noise. Without flat frames, the same on consecutive scene frames, which holds
  only where the view is still (said in the report).
- **FPA uniformity** (5.1): the RMS deviation of the time-averaged flat field from its mean, over
  good pixels, in percent of its mean signal in counts.
- **Temporal stability** (5.1): the slope of a line fitted to the flat frames' mean temperature
  against time, in °C per hour, with its standard error.
- **Absolute accuracy** (5.1): the blackbody frames' mean temperature against the blackbody's,
  passing within 5 °C or 5 % of the reading.
- **Linearity** (5.1): R² of the mean count against the blackbody temperature over this session
  and ``reference`` sessions (at least three temperatures).
- **Bad pixels** (5.3): the fraction in the session's bad-pixel map, and the fraction the data
  shows: pixels stuck (no temporal variation at all) or pinned at 0 or the top count.

What a session cannot support is reported as not measurable, with the reason, never as a number.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.radiometry.session import SessionTemperatures
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

__all__ = ["Measurement", "QualityReport", "measure_quality"]


@dataclass
class Measurement:
    requirement: str  # e.g. "NETD"
    icd: str  # the ICD section
    limit: str
    value: float | None
    unit: str
    passed: bool | None  # None: not measurable
    method: str
    detail: dict[str, Any] = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        return "not measurable" if self.passed is None else "pass" if self.passed else "fail"


@dataclass
class QualityReport:
    session_id: str
    frames: int
    flat_frames: int
    flat_source: str
    blackbody_c: float | None
    measurements: list[Measurement]
    series: dict[str, list[float]]  # the flat frames' (t_s, mean °C): the stability plot
    flat_mean: np.ndarray | None = field(default=None, repr=False)  # the time-averaged flat field, counts
    flat_level: float | None = None  # its mean over good pixels, counts
    model_versions: list[int] = field(default_factory=lambda: [0])  # the radiometric model versions used

    def to_dict(self) -> dict[str, Any]:
        return {"session_id": self.session_id, "frames": self.frames, "flat_frames": self.flat_frames,
                "model_versions": self.model_versions,
                "flat_source": self.flat_source, "blackbody_c": self.blackbody_c,
                "measurements": [{**asdict(m), "verdict": m.verdict} for m in self.measurements],
                "passed": all(m.passed is not False for m in self.measurements)}


class _Accumulator:
    """Per-pixel sums for a run of frames: mean, and the variance of consecutive differences."""

    def __init__(self) -> None:
        self.n = 0
        self.sum: np.ndarray | None = None
        self.diff_sq: np.ndarray | None = None
        self.pairs = 0
        self._prev: np.ndarray | None = None

    def add(self, f: np.ndarray, consecutive: bool) -> None:
        x = f.astype(np.float64)
        if self.sum is None:
            self.sum = np.zeros_like(x)
            self.diff_sq = np.zeros_like(x)
        self.sum += x
        self.n += 1
        if consecutive and self._prev is not None:
            assert self.diff_sq is not None
            self.diff_sq += (x - self._prev) ** 2
            self.pairs += 1
        self._prev = x

    def break_run(self) -> None:
        self._prev = None


def measure_quality(session_dir: str | Path, *, blackbody_c: float | None = None,
                    references: list[tuple[str | Path, float | None]] | None = None,
                    model_version: int | None = None) -> QualityReport:
    """The temperatures (the flat frames' means, the °C per count behind NETD) come from
    ``SessionTemperatures``, as every product's do: the model version covering each frame (or
    ``model_version`` for all), so a report after ``thermcap radiometry`` measures with the
    thermographer's parameters, and names the versions it used."""
    session_dir = Path(session_dir)
    meta = read_session_meta(session_dir)
    source = meta.get("source") or {}
    if blackbody_c is None and source.get("blackbody_c") is not None:
        blackbody_c = float(source["blackbody_c"])
    try:
        temps = SessionTemperatures.of(session_dir, meta, version=model_version)
    except ValueError as exc:
        raise ThermcapError(f"{session_dir.name}: {exc}") from None
    model = temps.base
    used: set[int] = set()
    flat, scene = _Accumulator(), _Accumulator()
    lo = hi = None  # per pixel: ever below the top, ever above 0; and any change
    first: np.ndarray | None = None
    changed: np.ndarray | None = None
    times: list[float] = []
    series_c: list[float] = []
    bpm = temps.bad_pixel_map
    n = 0
    t0 = None
    prev_index = -2
    bits = int(getattr(model, "bit_depth", 14) or 14)
    top = (1 << bits) - 1
    for fr in iter_session_frames(session_dir):
        px = fr.pixels
        n += 1
        if first is None:
            first = px.copy()
            changed = np.zeros(px.shape, bool)
            lo = np.zeros(px.shape, bool)
            hi = np.zeros(px.shape, bool)
        assert changed is not None and lo is not None and hi is not None
        changed |= px != first
        lo |= px < top
        hi |= px > 0
        t0 = fr.log_time if t0 is None else t0
        is_flat = blackbody_c is not None or bool((fr.sidecar_dict().get("capture") or {}).get("shutter_closed"))
        acc, other = (flat, scene) if is_flat else (scene, flat)
        acc.add(px, consecutive=fr.index == prev_index + 1)
        other.break_run()
        prev_index = fr.index
        if is_flat:  # the frame's mean temperature, without mapped (NaN) or pinned pixels
            ft = temps.celsius(fr.index, px)
            used.add(ft.model_version)
            model = ft.model
            valid = (px > 0) & (px < top) & np.isfinite(ft.celsius)
            times.append(round((fr.log_time - t0) / 1e9, 6))
            series_c.append(float(ft.celsius[valid].astype(np.float64).mean()))
    if n == 0 or first is None:
        raise ThermcapError(f"{session_dir}: no frames to measure")
    if not used:  # no flat frame: NETD's °C per count in the version of the last frame
        model = temps.model_for(prev_index if prev_index >= 0 else 0)[0]
    assert changed is not None and lo is not None and hi is not None
    # one frame cannot show a pixel stuck (nothing to change from): then only pinned ones count
    stuck = (~changed if n >= 2 else np.zeros_like(changed)) | ~lo | ~hi
    good = ~stuck
    flat_source = ("blackbody" if blackbody_c is not None else "shutter") if flat.n else "none"
    out: list[Measurement] = []
    if bpm is not None and bpm.shape == good.shape:
        good &= ~bpm
    series_t = times

    def c_per_count(level: float) -> float:
        """The model's °C per count at a level (the slope of a Planck or lookup model there), in
        the version of the last flat frame measured (else the last frame's)."""
        c = np.array([int(level), int(level) + 1], np.uint16)
        t = np.asarray(model.to_celsius(c), dtype=np.float64)
        return float(t[1] - t[0])

    # NETD
    netd_src, how = (flat, f"{flat_source} frames: consecutive differences") if flat.pairs else \
        (scene, "scene frames: consecutive differences (holds only where the view is still)")
    if netd_src.pairs:
        assert netd_src.diff_sq is not None and netd_src.sum is not None
        sigma = np.sqrt(netd_src.diff_sq / netd_src.pairs / 2)[good]
        level = float(np.median((netd_src.sum / netd_src.n)[good]))
        netd = float(np.median(sigma)) * c_per_count(level) * 1000
        out.append(Measurement("NETD", "5.2", "< 50 mK", round(netd, 2), "mK", netd < 50, how,
                               {"frame_pairs": netd_src.pairs, "counts_sigma": round(float(np.median(sigma)), 4)}))
    else:
        out.append(Measurement("NETD", "5.2", "< 50 mK", None, "mK", None, "needs two consecutive frames"))
    flat_mean = None
    if flat.n:
        assert flat.sum is not None
        flat_mean = flat.sum / flat.n
        m = float(flat_mean[good].mean())
        rms = float(np.sqrt(np.mean((flat_mean[good] - m) ** 2)))
        out.append(Measurement("FPA uniformity", "5.1", "< 2 % RMS", round(rms / m * 100, 4) if m else None, "%",
                               (rms / m * 100) < 2 if m else None,
                               f"time-averaged {flat_source} field over {flat.n} frames, good pixels",
                               {"rms_counts": round(rms, 4), "mean_counts": round(m, 2)}))
    else:
        out.append(Measurement("FPA uniformity", "5.1", "< 2 % RMS", None, "%", None,
                               "no flat field: record a blackbody (--blackbody) or shutter frames"))
    if len(series_t) >= 3 and series_t[-1] - series_t[0] > 0:
        slope, se = _fit_slope(np.array(series_t), np.array(series_c))
        per_h, se_h = slope * 3600, se * 3600
        span = series_t[-1] - series_t[0]
        out.append(Measurement("Temporal stability", "5.1", "< 1 °C/h", round(per_h, 4), "°C/h", abs(per_h) < 1,
                               f"line fitted to the {flat_source} frames' mean temperature over {span:.0f} s",
                               {"standard_error_c_per_h": round(se_h, 4), "span_s": round(span, 1),
                                "points": len(series_t)}))
    else:
        out.append(Measurement("Temporal stability", "5.1", "< 1 °C/h", None, "°C/h", None,
                               "no reference: needs flat frames (blackbody or shutter) at three times or more"))
    if blackbody_c is not None and series_c:
        measured = float(np.mean(series_c))
        err = measured - blackbody_c
        tol = max(5.0, 0.05 * abs(measured))
        out.append(Measurement("Absolute accuracy", "5.1", "±5 °C or 5 % of reading", round(err, 4), "°C",
                               abs(err) <= tol, f"mean of the blackbody frames ({measured:.3f} °C) against "
                                                f"{blackbody_c:g} °C", {"measured_c": round(measured, 4)}))
    else:
        out.append(Measurement("Absolute accuracy", "5.1", "±5 °C or 5 % of reading", None, "°C", None,
                               "no blackbody: give --blackbody TEMP_C for a session that looks at one"))
    out.append(_linearity(blackbody_c, flat_mean, good, references or []))
    data_frac = float(stuck.mean())
    detail: dict[str, Any] = {"from_data": round(data_frac * 100, 4), "stuck_pixels": int(stuck.sum())}
    map_frac = float(bpm.mean()) if bpm is not None else 0.0
    if bpm is not None:
        detail["from_map"] = round(map_frac * 100, 4)
        detail["map_pixels"] = int(bpm.sum())
    worst = max(data_frac, map_frac) * 100
    out.append(Measurement("Bad pixels", "5.3", "< 0.1 %", round(worst, 4), "%", worst < 0.1,
                           "the bad-pixel map, and pixels the data shows stuck or pinned at 0 or the top count"
                           + ("" if n >= 30 else f" (only {n} frames: a still pixel may look stuck)"), detail))
    return QualityReport(meta.get("session_id", session_dir.name), n, flat.n, flat_source, blackbody_c, out,
                         {"t_s": series_t, "mean_c": series_c}, flat_mean,
                         float(flat_mean[good].mean()) if flat_mean is not None else None,
                         sorted(used) or [temps.model_for(max(0, n - 1))[1]])


def _fit_slope(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    tm = t - t.mean()
    slope = float((tm * (y - y.mean())).sum() / (tm ** 2).sum())
    resid = y - y.mean() - slope * tm
    dof = max(len(t) - 2, 1)
    se = math.sqrt(float((resid ** 2).sum()) / dof / float((tm ** 2).sum()))
    return slope, se


def _linearity(blackbody_c: float | None, flat_mean: np.ndarray | None, good: np.ndarray,
               references: list[tuple[str | Path, float | None]]) -> Measurement:
    points: list[tuple[float, float]] = []
    if blackbody_c is not None and flat_mean is not None:
        points.append((blackbody_c, float(flat_mean[good].mean())))
    for ref, temp in references:
        rep = measure_quality(ref, blackbody_c=temp)
        if rep.blackbody_c is None or rep.flat_level is None:
            raise ThermcapError(f"{ref}: a reference session needs its blackbody temperature (SESSION=TEMP_C)")
        points.append((rep.blackbody_c, rep.flat_level))
    temps = {round(t, 6) for t, _ in points}
    if len(temps) < 3:
        return Measurement("Linearity", "5.1", "R² > 0.99", None, "R²", None,
                           f"needs blackbody frames at three temperatures or more ({len(temps)} given: this session's "
                           f"--blackbody and --reference SESSION=TEMP_C)")
    x = np.array([p[0] for p in points])
    y = np.array([p[1] for p in points])
    a, b = np.polyfit(x, y, 1)
    ss_res = float(((y - (a * x + b)) ** 2).sum())
    ss_tot = float(((y - y.mean()) ** 2).sum())
    r2 = 1 - ss_res / ss_tot if ss_tot else 0.0
    return Measurement("Linearity", "5.1", "R² > 0.99", round(r2, 6), "R²", r2 > 0.99,
                       f"mean count against blackbody temperature at {len(points)} points",
                       {"points": [[round(t, 3), round(c, 3)] for t, c in points],
                        "counts_per_c": round(float(a), 5)})
