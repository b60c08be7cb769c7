"""``--source`` values: ``[NAME=]KIND[,key=value...]``, one per camera.

``sim``, ``raw:PATH`` and ``raw:-`` as before; a name puts the camera under
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
    kind: str  # "sim", "raw:PATH", "raw:-"
    name: str | None = None
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def is_sim(self) -> bool:
        return self.kind == "sim"


def parse_source_spec(text: str) -> SourceSpec:
    head, *pairs = text.split(",")
    name = None
    if "=" in head and (":" not in head or head.index("=") < head.index(":")):
        name, head = head.split("=", 1)
        try:
            check_camera_name(name)
        except ValueError as exc:
            raise SourceError(f"--source {text!r}: {exc}") from None
    if head != "sim" and not head.startswith("raw:"):
        raise SourceError(f"--source {text!r}: unknown source {head!r}: use 'sim', 'raw:PATH' or 'raw:-' for stdin")
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
