"""The one place a frame is taken from a copy and checked before anyone uses it.

A session may hold a frame several times: in its MCAP source, in each archive format, on local
disk or in a bucket. Whoever reads a frame (the API's routes, ``thermcap.open`` on a folder or a
bucket, ``cut``, exports) lists the copies it can reach as ``Copy`` values and asks
``read_verified`` for a part of the frame. The copies are tried cheapest first (each format's
declared ``ReadCost``), each one's answer is hashed and compared with the manifest's digest, and a
copy that fails is reported as damage and passed over; a missing one is passed over quietly. So
the check and the damage report live here once, and a new reader cannot forget them.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from thermcap.archive.exceptions import FrameNotFound, FrameUnavailable
from thermcap.archive.formats.base import ReadCost
from thermcap.recorder.storage.digest import FrameProof, bytes_digest, frame_digest

__all__ = [
    "Copy",
    "Damage",
    "DamageLog",
    "Part",
    "counts_of",
    "differs",
    "in_read_order",
    "read_verified",
    "sidecar_of",
    "unoffered",
    "wanted",
]

log = logging.getLogger("thermcap.archive")

Part = Literal["pixels", "sidecar"]


@dataclass(frozen=True)
class Copy:
    """One place a frame can be read from: ``read(part)`` gives its pixels (an array) or its
    sidecar (the JSON bytes as recorded); it raises ``FrameNotFound`` or ``FileNotFoundError``
    where this copy does not hold the frame, anything else where it is damaged."""

    name: str  # "png16:0000.zip", "mcap:0001.mcap", "hdf5:session.h5"
    cost: ReadCost
    read: Callable[[Part], Any]


#: Where a copy not offered whole ranks: scrub marked a file of it damaged, or it never verified.
#: It is read after every offered copy; a damaged file hides only the frames it holds, and each
#: frame read from it is checked like any other.
_UNOFFERED = 10**7


def unoffered(cost: ReadCost) -> ReadCost:
    """``cost`` moved behind every copy that is offered whole, keeping its order among the rest."""
    return ReadCost(_UNOFFERED + cost.frame, _UNOFFERED + cost.stream)


def in_read_order(copies: Iterable[Copy], *, stream: bool = False) -> list[Copy]:
    """Cheapest first, by the cost of one frame alone or, with ``stream``, of every frame in order."""
    return sorted(copies, key=lambda c: (c.cost.stream, c.cost.frame) if stream else (c.cost.frame, c.cost.stream))


@dataclass
class Damage:
    session_id: str
    frame: int
    copy: str  # which copy: "png16:0000.zip", "mcap:0000.mcap", "hdf5:<id>.h5"
    problem: str
    at: float = field(default_factory=time.time)


class DamageLog:
    """Damaged copies met while reading: logged, counted (``counter``, a prometheus Counter the
    server sets) and kept for /healthz; a bounded list of the latest, so a bad disk cannot fill
    memory."""

    def __init__(self, keep: int = 100) -> None:
        self.recent: deque[Damage] = deque(maxlen=keep)
        self.total = 0
        self.counter: Any = None
        self._lock = threading.Lock()

    def report(self, damage: Damage) -> None:
        with self._lock:
            self.total += 1
            self.recent.append(damage)
        log.warning("damaged copy of frame %d of %s in %s: %s; reading another verified copy",
                    damage.frame, damage.session_id, damage.copy, damage.problem)
        if self.counter is not None:
            self.counter.labels(damage.copy.split(":", 1)[0]).inc()

    def summary(self) -> dict[str, Any]:
        with self._lock:
            return {"damaged_copies_seen": self.total,
                    "recent": [{"session_id": d.session_id, "frame": d.frame, "copy": d.copy, "problem": d.problem}
                               for d in list(self.recent)[-10:]]}


def wanted(proof: FrameProof, frame: int, part: Part) -> str | None:
    """The manifest's digest of a frame's part, None where it has none (not archived yet)."""
    digests = proof.pixels if part == "pixels" else proof.sidecars
    return digests[frame] if 0 <= frame < len(digests) else None


def counts_of(value: Any) -> np.ndarray:
    """A verified frame's pixels as the readers hand them out: uint16, read-only (a recorded
    count never changes, and a cache may share the array)."""
    px = np.asarray(value, dtype=np.uint16)
    px.setflags(write=False)
    return px


def sidecar_of(value: Any) -> dict[str, Any]:
    """A verified sidecar's JSON bytes as a dict (an empty one where the frame had none)."""
    return dict(json.loads(value or b"{}"))


def differs(part: Part, value: Any, want: str | None, hash_name: str) -> bool:
    """True where a frame's part read from a copy does not hash to the manifest's digest (False
    where there is no digest to compare with)."""
    if not want:
        return False
    return (frame_digest(value, hash_name) if part == "pixels" else bytes_digest(value, hash_name)) != want


def read_verified(copies: Iterable[Copy], part: Part, *, session_id: str, frame: int, want: str | None,
                  hash_name: str, damage: DamageLog, where: str = "") -> Any:
    """Frame ``frame``'s ``part`` from the first of ``copies`` (taken in the order given) whose
    bytes hash (``hash_name``) to ``want``, the manifest's digest. With no digest (a session not
    archived yet) the MCAP chunk's own CRC, checked by its reader, is the only proof there is.

    Raises ``FrameUnavailable`` naming each copy's problem when none gives a verified answer."""
    problems: list[str] = []
    for copy in copies:
        try:
            value = copy.read(part)
        except (FrameNotFound, FileNotFoundError) as exc:
            problems.append(f"{copy.name}: {exc}")
            continue
        except Exception as exc:  # a damaged file may fail anywhere inside a decoder
            problem = f"unreadable ({type(exc).__name__}: {exc})"
            damage.report(Damage(session_id, frame, copy.name, problem))
            problems.append(f"{copy.name}: {problem}")
            continue
        if differs(part, value, want, hash_name):
            problem = f"{part} {hash_name} differs from the manifest"
            damage.report(Damage(session_id, frame, copy.name, problem))
            problems.append(f"{copy.name}: {problem}")
            continue
        return value
    raise FrameUnavailable(f"frame {frame} of {where or session_id}: no verified copy could be read"
                           + (f" ({'; '.join(problems)})" if problems else " (no copy holds it)"))
