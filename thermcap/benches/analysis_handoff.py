"""``thermcap bench analysis``'s hand-off line: what the recording process pays, a frame, to
give a frame to the detector's process and take its answer back.

With analysis on, a file source's rate is bound by the two cores the recording and the detector
share (issue #40's goal: >= 0.5x the rate without analysis), and on a flat scene the detector's
own work is the smaller part: the recording process copies the frame into a shared slot, sends
its number, and its results thread wakes for the answer. The line measures that process's CPU a
frame over a burst of frames, with the child sending its results in batches while it is behind
(as recordings do) against one message a frame (as before), alternated in the same run; and a
flat frame, which the recording process answers itself."""

from __future__ import annotations

import statistics
import time
from concurrent.futures import Future
from typing import Any

import numpy as np

from thermcap.recorder.analysis.detector import HotSpotDetector
from thermcap.recorder.analysis.process_runner import ProcessRunner
from thermcap.recorder.capture.recorder import FILE_ANALYSIS_SLOTS
from thermcap.recorder.radiometry import DEFAULT_MODEL

__all__ = ["handoff_cpu"]

def _burst(frame: np.ndarray, frames: int, batch: int | None) -> tuple[float, int]:
    """The recording process's CPU microseconds a frame for ``frames`` frames handed to a fresh
    child, and how many messages of answers came back."""
    runner = ProcessRunner(HotSpotDetector(DEFAULT_MODEL), slots=FILE_ANALYSIS_SLOTS, frame_bytes=frame.nbytes,
                           batch=batch)
    try:
        futs: list[Future] = [Future() for _ in range(frames)]
        cpu = time.process_time()
        for fut in futs:
            if not runner.submit(frame, fut, wait=True):
                raise RuntimeError(f"the detector process stopped taking frames: {runner.failure}")
        for fut in futs:
            fut.result(timeout=120)
        cpu = time.process_time() - cpu
        return 1e6 * cpu / frames, runner.answer_messages
    finally:
        runner.close(30)


def handoff_cpu(frames: int = 2000, rounds: int = 3, size: tuple[int, int] = (640, 512)) -> dict[str, Any]:
    """The median over ``rounds`` alternated pairs, on a flat frame with one warm pixel: the
    detector's cheapest frame that still travels (a frame too flat for any candidate is
    answered in the recording process and never does, ``HotSpotDetector.flat_answer``), so the
    hand-off is most of what analysis costs the recording process. Beside it, what the flat
    frame itself costs that process."""
    w, h = size
    frame = np.full((h, w), 2000, np.uint16)
    frame[0, 0] += 400  # one pixel 14 K above the rest: not flat, and no target (below min_area)
    batched, single, messages, flat = [], [], [], []
    for _ in range(rounds):
        us, msgs = _burst(frame, frames, None)
        batched.append(us)
        messages.append(msgs)
        single.append(_burst(frame, frames, 1)[0])
        flat.append(_burst(np.full((h, w), 2000, np.uint16), frames, None)[0])
    b, s = statistics.median(batched), statistics.median(single)
    return {"size": f"{w}x{h}", "frames": frames, "rounds": rounds,
            "recording_cpu_us_per_frame_batched": round(b, 1),
            "recording_cpu_us_per_frame_one_message_a_frame": round(s, 1),
            "batched_vs_one_message_a_frame": round(b / s, 3),
            "answer_messages_batched": int(statistics.median(messages)),
            "recording_cpu_us_per_frame_flat_answered_here": round(statistics.median(flat), 1)}
