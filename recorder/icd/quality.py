"""Image-quality metrics of the ICD: contrast grade and metrics (7.1), NETD (5.2), bad pixels (5.3).

These follow the ICD's reference code exactly (same statistics, same epsilons), so a grade
computed here equals the grade the ICD's own implementation would give on the same masks.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from thermcap.recorder.icd.names import DETECTION_THRESHOLD_K, EXCELLENT_THRESHOLD_K

__all__ = [
    "contrast_grade",
    "contrast_metrics",
    "correct_bad_pixels",
    "frame_analysis",
    "netd_mk",
    "snr_db",
]


def contrast_grade(delta_t: float) -> float:
    """ICD 4.3.1: 0 below 5 K, a linear ramp to 1 at 10 K, 1 above."""
    if delta_t < DETECTION_THRESHOLD_K:
        return 0.0
    if delta_t < EXCELLENT_THRESHOLD_K:
        return (delta_t - DETECTION_THRESHOLD_K) / (EXCELLENT_THRESHOLD_K - DETECTION_THRESHOLD_K)
    return 1.0


def snr_db(delta_t: float, target_std: float, background_std: float) -> float:
    """ICD 7.1's SNR: delta T over the summed standard deviations, in dB (10 log10)."""
    snr = delta_t / (target_std + background_std + 1e-6)
    return float(10.0 * np.log10(snr + 1e-6)) if snr + 1e-6 > 0 else float("-inf")


def contrast_metrics(temp_c: np.ndarray, target_mask: np.ndarray, background_mask: np.ndarray) -> dict[str, Any]:
    """ICD 7.1 ``calculate_thermal_contrast_grade`` on a temperature map and two boolean masks.

    Returns the ICD's metrics dict (floats). Empty masks are an error: the ICD's code would
    fail on ``np.max`` of nothing, and a grade from no pixels would be meaningless.
    """
    target = np.asarray(temp_c)[target_mask]
    background = np.asarray(temp_c)[background_mask]
    if target.size == 0 or background.size == 0:
        raise ValueError(
            f"contrast metrics need target and background pixels (got {target.size} and {background.size})"
        )
    max_target = float(np.max(target))
    min_background = float(np.min(background))
    delta_t = max_target - min_background
    return {
        "max_target_temp_c": max_target,
        "mean_target_temp_c": float(np.mean(target)),
        "min_background_temp_c": min_background,
        "mean_background_temp_c": float(np.mean(background)),
        "delta_t_deg_c": delta_t,
        "snr_db": snr_db(delta_t, float(np.std(target)), float(np.std(background))),
        "thermal_contrast_grade": contrast_grade(delta_t),
    }


def frame_analysis(per_target: list[dict[str, Any]], *, source: str, confidence: float | None) -> dict[str, Any]:
    """The sidecar's ``thermal_analysis`` block from per-target ICD 7.1 metrics.

    Each target is graded against its own local background; the frame reports its most
    detectable target (largest delta T). Pooling all targets and all backgrounds into two masks
    would pit a warm vehicle on the ground against the cold sky behind a drone and never show
    a crossover. With no target the grade is 0 and the undefined metrics are null.
    """
    if not per_target:
        return {"thermal_contrast_grade": 0.0, "max_target_temp_c": None, "min_background_temp_c": None,
                "delta_t_deg_c": None, "snr_db": None, "detection_confidence": None, "source": source}
    best = max(per_target, key=lambda m: m["delta_t_deg_c"])
    return {
        "thermal_contrast_grade": round(best["thermal_contrast_grade"], 6),
        "max_target_temp_c": round(best["max_target_temp_c"], 3),
        "min_background_temp_c": round(best["min_background_temp_c"], 3),
        "delta_t_deg_c": round(best["delta_t_deg_c"], 3),
        "snr_db": round(best["snr_db"], 3),
        "detection_confidence": confidence,
        "source": source,
    }


def graded_contrast(thermal_analysis: dict[str, Any] | None) -> float | None:
    """The frame's contrast grade, or None when there was nothing to grade.

    A sidecar always carries a number (the ICD field is required), but 0.0 on a frame that was
    not analysed, or that had no target in view, is a placeholder, not a measurement: such a frame
    is neither a crossover nor a good frame, and search filters must not count it as either."""
    ta = thermal_analysis or {}
    grade = ta.get("thermal_contrast_grade")
    if grade is None or ta.get("source") in ("skipped", "none") or ta.get("delta_t_deg_c") is None:
        return None
    return float(grade)


def netd_mk(uniform_frame: np.ndarray, scale_c_per_count: float) -> float:
    """ICD 5.2: NETD in mK from one image of a uniform (blackbody) scene.

    Note that a single frame's spatial std includes fixed-pattern noise; for temporal NETD,
    pass the difference of two frames divided by sqrt(2) (still uniform, FPN cancelled).
    """
    return float(np.std(np.asarray(uniform_frame, dtype=np.float64)) * scale_c_per_count * 1000.0)


def correct_bad_pixels(frame: np.ndarray, bad_pixel_map: np.ndarray) -> np.ndarray:
    """ICD 5.3: replace each bad pixel by the median of its good 8-neighbours.

    Returns a new array; the input (the recorded raw counts) is never altered, since the
    archive keeps what the sensor produced. A bad pixel whose neighbours are all bad keeps the
    median of the nearest good pixels found by widening the window.
    """
    frame = np.asarray(frame)
    bpm = np.asarray(bad_pixel_map, dtype=bool)
    if bpm.shape != frame.shape:
        raise ValueError(f"bad-pixel map shape {bpm.shape} does not match the frame {frame.shape}")
    out = frame.copy()
    h, w = frame.shape
    for y, x in zip(*np.nonzero(bpm), strict=True):
        for radius in range(1, max(h, w)):
            y0, y1, x0, x1 = max(0, y - radius), min(h, y + radius + 1), max(0, x - radius), min(w, x + radius + 1)
            good = frame[y0:y1, x0:x1][~bpm[y0:y1, x0:x1]]
            if good.size:
                out[y, x] = np.median(good).round().astype(frame.dtype) if frame.dtype.kind in "ui" else np.median(good)
                break
    return out

