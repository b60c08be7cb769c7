"""``--source`` values: ``[NAME=]KIND[,key=value...]``, one per camera.

The kinds are those registered (``registry.py``): ``sim``, ``raw:PATH``, ``raw:-``,
``gige:CAMERA`` and ``exec:COMMAND`` (the rest of the value is the command, commas and all, so
it takes no ``,key=value`` of its own: the command's ``--width`` and the like apply). A GigE
camera also takes GenICam features as keys (``ExposureTime=8000``). A name puts the camera under
``/thermal/<name>/`` in a session of several (``left=sim,width=320,height=256,fps=30``). Keys
given here override the command's own ``--width``/``--fps``/... for that camera only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from thermcap.recorder.capture.sources.registry import SourceKind, kind_of
from thermcap.recorder.exceptions import SourceError
from thermcap.recorder.icd.topics import check_camera_name

__all__ = ["CAMERA_KEYS", "SourceSpec", "accepts_key", "parse_source_spec"]

#: per-camera keys and how their text is read
CAMERA_KEYS: dict[str, Any] = {
    "width": int, "height": int, "fps": float, "seed": int, "sensor": str, "timestamps": str,
    "pace": lambda v: _bool(v), "crossover": lambda v: _bool(v), "cue-period": float,
}


def _bool(v: str | bool) -> bool:
    if isinstance(v, bool):
        return v
    if v.lower() in ("1", "true", "yes", "on"):
        return True
    if v.lower() in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"{v!r} is not true or false")


@dataclass(frozen=True)
class SourceSpec:
    kind: str  # "sim", "raw:PATH", "raw:-", "exec:COMMAND", "gige:CAMERA"
    name: str | None = None
    options: dict[str, Any] = field(default_factory=dict)  # common keys parsed; the kind's own under "own"

    @property
    def source_kind(self) -> SourceKind:
        return kind_of(self.kind)

    @property
    def target(self) -> str:
        """The text after ``scheme:`` (a path, a command, a camera), empty for ``sim``."""
        return self.kind.split(":", 1)[1] if ":" in self.kind else ""


def parse_source_spec(text: str) -> SourceSpec:
    name, rest = _name(text)
    head = rest.split(",", 1)[0]
    try:
        kind = kind_of(head)
    except SourceError as exc:
        raise SourceError(f"--source {text!r}: {exc}") from None
    if kind.whole_rest:  # the rest is the target, commas and all (ffmpeg's filters have them)
        if not rest.split(":", 1)[1].strip():
            raise SourceError(f"--source {text!r}: {kind.scheme}: needs a target ({kind.usage})")
        return SourceSpec(kind=rest, name=name)
    head, *pairs = rest.split(",")
    if head != kind.scheme and not head.split(":", 1)[1] and not kind.target_optional:
        raise SourceError(f"--source {text!r}: {kind.scheme}: needs a target ({kind.usage})")
    options: dict[str, Any] = {}
    own: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if sep and kind.own_key is not None and kind.own_key(key):
            own[key] = value.strip()
            continue
        key = key.replace("_", "-")
        if not sep or key not in CAMERA_KEYS:
            raise SourceError(f"--source {text!r}: {pair!r} is not one of "
                              f"{', '.join(k + '=...' for k in CAMERA_KEYS)}"
                              + (" or a feature of the camera (Name=value)" if kind.own_key is not None else ""))
        try:
            options[key] = CAMERA_KEYS[key](value.strip())
        except ValueError as exc:
            raise SourceError(f"--source {text!r}: {key}: {exc}") from None
    if own:
        options["own"] = own
    return SourceSpec(kind=head, name=name, options=options)


def accepts_key(source: str, key: str) -> bool:
    """Whether a ``--source`` of this kind takes ``key`` (a config file's camera table checks with it)."""
    if key.replace("_", "-") in CAMERA_KEYS:
        return True
    try:
        kind = kind_of(str(source).split(",", 1)[0])
    except SourceError:
        return False
    return kind.own_key is not None and kind.own_key(key)


def _name(text: str) -> tuple[str | None, str]:
    """``NAME=`` before the kind, if any (checked as a camera name), and the rest."""
    head = text.split(",", 1)[0]
    if "=" in head and (":" not in head or head.index("=") < head.index(":")):
        name, rest = text.split("=", 1)
        try:
            check_camera_name(name)
        except ValueError as exc:
            raise SourceError(f"--source {text!r}: {exc}") from None
        return name, rest
    return None, text
