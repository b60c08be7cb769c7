"""Frame sources: ``make_source`` turns a ``--source`` argument into one."""

from __future__ import annotations

from typing import Any

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, Pacer, SensorInfo
from thermcap.recorder.capture.sources.command import CommandSource
from thermcap.recorder.capture.sources.raw import RawSource
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import SourceError

__all__ = ["CapturedFrame", "CommandSource", "FrameSource", "Pacer", "RawSource", "SensorInfo", "SimSource",
           "make_source"]


def make_source(spec: str, **options: Any) -> FrameSource:
    """``sim``, ``raw:PATH`` / ``raw:-`` (stdin) or ``exec:COMMAND`` -> a FrameSource."""
    if spec == "sim":
        keep = {"width", "height", "fps", "seed", "frames", "duration_s", "paced", "crossover", "cue_period_s",
                "start_time_ns", "sensor_id"}
        return SimSource(**{k: v for k, v in options.items() if k in keep and v is not None})
    if spec.startswith("exec:"):
        keep = {"width", "height", "fps", "sensor_id", "model", "max_frames"}
        return CommandSource(spec[5:], **{k: v for k, v in options.items() if k in keep and v is not None})
    if spec.startswith("raw:"):
        keep = {"width", "height", "fps", "paced", "sensor_id", "model", "max_frames", "timestamps"}
        return RawSource(spec[4:], **{k: v for k, v in options.items() if k in keep and v is not None})
    raise SourceError(f"unknown source {spec!r}: use 'sim', 'raw:PATH', 'raw:-' for stdin or 'exec:COMMAND'")
