"""Where each kind of frame source is registered, with what it takes from the command line.

A source is one module: its ``FrameSource`` and a ``SourceKind`` registered here under the
scheme it answers to in ``--source`` (``sim``, ``raw:PATH``, ``exec:COMMAND``, ``gige:CAMERA``).
The command line fills one ``CameraSettings`` per camera (its flags, then the ``--source``
text's own ``,key=value`` pairs) and the kind builds its source from it; nothing else in
thermcap names a kind of source.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, cast

from thermcap.recorder.capture.sources.base import FrameSource
from thermcap.recorder.exceptions import SourceError
from thermcap.recorder.registry import Registry

__all__ = ["CameraSettings", "SourceKind", "kind_of", "register_source", "source_registry"]


@dataclass(frozen=True)
class CameraSettings:
    """One camera's settings: the command's flags, overridden by its ``--source`` keys."""

    width: int = 640
    height: int = 512
    fps: float = 60.0
    sensor_id: str | None = None
    pace: bool | None = None  # None: the kind's own default
    timestamps: str = "stream"
    seed: int = 0
    crossover: bool = False
    cue_period_s: float = 20.0
    duration_s: float | None = None  # the recording's --duration
    #: the kind's own ``,key=value`` pairs (a GigE camera's GenICam features), as given
    own: Mapping[str, str] = field(default_factory=dict)


def _unknown(key: str, known: list[str]) -> SourceError:
    return SourceError(f"unknown source {key!r}: use {describe_kinds()}")


@dataclass(frozen=True)
class SourceKind:
    """A kind of source: how ``--source`` names it and how it is built from settings."""

    scheme: str  # "sim", or the part before ':' ("raw", "exec", "gige")
    usage: str  # how it is written: "raw:PATH"
    build_source: Callable[[str, CameraSettings], FrameSource]  # (the text after "scheme:", settings)
    #: the rest of the text is the target, commas and all (a command line): no ,key=value pairs
    whole_rest: bool = False
    #: keys of its own besides the common ones (a GigE camera's GenICam features: CamelCase names)
    own_key: Callable[[str], bool] | None = None
    #: it ends by itself at --duration (the simulator makes exactly duration x fps frames)
    counts_duration: bool = False
    #: frames released at --fps unless --pace says otherwise
    paced_by_default: bool = False
    #: ``scheme:`` alone means something (a GigE camera: the first one found)
    target_optional: bool = False

    def __call__(self, target: str, settings: CameraSettings) -> FrameSource:
        return self.build_source(target, settings)


source_registry: Registry[FrameSource] = Registry("source", _unknown)


def register_source(kind: SourceKind) -> SourceKind:
    source_registry.register(kind.scheme, kind)
    return kind


def kind_of(text: str) -> SourceKind:
    """The kind a ``--source`` head names (``sim``, ``raw:...``); unknown ones name the known."""
    scheme = text.split(":", 1)[0] if ":" in text else text
    return cast(SourceKind, source_registry.factory(scheme))


def describe_kinds() -> str:
    return ", ".join(cast(SourceKind, k).usage for k in source_registry.values())


def settings_from(options: Mapping[str, Any], defaults: CameraSettings) -> CameraSettings:
    """``defaults`` with a ``--source``'s parsed common keys (``width``, ``cue-period``, ...) and own ones."""
    renamed = {"sensor": "sensor_id", "cue-period": "cue_period_s"}
    common = {renamed.get(k, k): v for k, v in options.items() if k != "own"}
    return CameraSettings(**{**defaults.__dict__, **common, "own": dict(options.get("own") or {})})
