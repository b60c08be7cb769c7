"""A frame's answer from the detector, the same whichever runner (thread or child process)
produced it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from thermcap.recorder.analysis.detector import HotSpotDetector
from thermcap.recorder.radiometry import TemperatureUnavailable

__all__ = ["Unanalysable", "analyse_one"]


@dataclass(frozen=True)
class Unanalysable:
    """The detector's answer for a frame with no temperature (not a fault: the reason is kept)."""

    why: str


def analyse_one(detector: HotSpotDetector, pixels: np.ndarray) -> Any:
    """One frame's answer as both runners give it: a detector failure must not stop recording,
    so it becomes ``None`` (the frame says skipped)."""
    try:
        return detector.detect(pixels)
    except TemperatureUnavailable as exc:
        return Unanalysable(str(exc))
    except Exception:
        return None
