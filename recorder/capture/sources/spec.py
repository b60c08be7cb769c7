"""``--source`` values: ``[NAME=]KIND[,key=value...]``, one per camera.

``sim``, ``raw:PATH``, ``raw:-`` and ``exec:COMMAND`` (the rest of the value is the command,
commas and all, so it takes no ``,key=value`` of its own: the command's ``--width`` and the
like apply); a name puts the camera under
``/thermal/<name>/`` in a session of several (``left=sim,width=320,height=256,fps=30``). Keys
given here override the command's own ``--width``/``--fps``/... for that camera only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from thermcap.recorder.exceptions import SourceError
from thermcap.recorder.icd.topics import check_camera_name

__all__ = ["CAMERA_KEYS", "SourceSpec", "parse_source_spec"]

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
    kind: str  # "sim", "raw:PATH", "raw:-", "exec:COMMAND"
    name: str | None = None
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def is_sim(self) -> bool:
        return self.kind == "sim"


def parse_source_spec(text: str) -> SourceSpec:
    name, rest = _name(text)
    if rest.startswith("exec:"):  # the rest is the command, commas and all (ffmpeg's filters have them)
        if not rest[5:].strip():
            raise SourceError(f"--source {text!r}: exec: needs a command (exec:COMMAND ARGS...)")
        return SourceSpec(kind=rest, name=name)
    head, *pairs = rest.split(",")
    if head != "sim" and not head.startswith("raw:"):
        raise SourceError(f"--source {text!r}: unknown source {head!r}: use 'sim', 'raw:PATH', 'raw:-' for stdin "
                          f"or 'exec:COMMAND'")
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip().replace("_", "-")
        if not sep or key not in CAMERA_KEYS:
            raise SourceError(f"--source {text!r}: {pair!r} is not one of "
                              f"{', '.join(k + '=...' for k in CAMERA_KEYS)}")
        try:
            options[key] = CAMERA_KEYS[key](value.strip())
        except ValueError as exc:
            raise SourceError(f"--source {text!r}: {key}: {exc}") from None
    return SourceSpec(kind=head, name=name, options=options)


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
