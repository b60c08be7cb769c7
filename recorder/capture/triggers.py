"""What starts an event window while recording: the detector (a new hot spot above a threshold,
a change in target count, the contrast grade falling under the ICD's 0.3 crossover), a radar cue
(ICD section 8), and marks from ``thermcap ctl mark`` or SIGUSR1. Each trigger fires on an edge,
not on every frame it stays true, so a long hot spot is one window, not thousands."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from thermcap.recorder.icd.names import CROSSOVER_GRADE
from thermcap.recorder.icd.quality import graded_contrast

__all__ = ["TriggerPolicy", "TriggerWatch"]


@dataclass(frozen=True)
class TriggerPolicy:
    hot_spot_c: float | None = None  # a target hotter than this appears
    target_count: bool = False  # the number of targets changes
    crossover: bool = True  # the contrast grade falls under 0.3
    radar_cue: bool = True  # a radar cue is received


class TriggerWatch:
    def __init__(self, policy: TriggerPolicy) -> None:
        self.policy = policy
        self._hot = False
        self._targets: int | None = None
        self._low = False
        self._cue = False

    def check(self, blocks: dict[str, Any]) -> list[str]:
        """The triggers this frame's sidecar blocks fire (edges only)."""
        p, fired = self.policy, []
        targets = blocks.get("targets") or []
        if p.hot_spot_c is not None:
            hot = any((t.get("max_temp_c") or float("-inf")) >= p.hot_spot_c for t in targets)
            if hot and not self._hot:
                fired.append(f"hot_spot: a target at or above {p.hot_spot_c} degC")
            self._hot = hot
        if p.target_count:
            if self._targets is not None and len(targets) != self._targets:
                fired.append(f"target_count: {self._targets} -> {len(targets)}")
            self._targets = len(targets)
        if p.crossover:
            grade = graded_contrast(blocks.get("thermal_analysis"))
            low = grade is not None and grade < CROSSOVER_GRADE
            if low and not self._low:
                fired.append(f"crossover: contrast grade {grade:.3f} under {CROSSOVER_GRADE}")
            if grade is not None:
                self._low = low
        if p.radar_cue:
            cue = bool((blocks.get("slew_to_cue") or {}).get("radar_cue_received"))
            if cue and not self._cue:
                fired.append("radar_cue: cue received")
            self._cue = cue
        return fired
