"""Frame sources: ``make_source`` turns a ``--source`` argument into one.

Each kind is one module that registers itself (``registry.py``); importing this package
registers them all. The GigE source imports Aravis only when a camera is opened.
"""

from __future__ import annotations

from thermcap.recorder.capture.sources import command, gige, raw, sim  # noqa: F401 - each registers its kind
from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, Pacer, SensorInfo
from thermcap.recorder.capture.sources.command import CommandSource
from thermcap.recorder.capture.sources.raw import RawSource
from thermcap.recorder.capture.sources.registry import CameraSettings, kind_of, source_registry
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.capture.sources.spec import SourceSpec, parse_source_spec

__all__ = ["CameraSettings", "CapturedFrame", "CommandSource", "FrameSource", "Pacer", "RawSource", "SensorInfo",
           "SimSource", "SourceSpec", "make_source", "source_registry"]


def make_source(spec: str | SourceSpec, settings: CameraSettings | None = None) -> FrameSource:
    """``sim``, ``raw:PATH``, ``exec:COMMAND``, ``gige:CAMERA`` (with ``,key=value`` pairs) -> a FrameSource."""
    from thermcap.recorder.capture.sources.registry import settings_from

    sp = parse_source_spec(spec) if isinstance(spec, str) else spec
    kind = kind_of(sp.kind)
    return kind(sp.target, settings_from(sp.options, settings or CameraSettings()))
