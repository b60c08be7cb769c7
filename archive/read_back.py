"""What a freshly written copy is read back against, and the digest that comparison uses.

The manifest's proof of record is each frame's digest (BLAKE3, or sha256 in older manifests),
taken on the archiver's one read of the source; ``verify``, ``scrub`` and every step that deletes
compare copies with it. The writer's own read-back, right after writing, used to take a sha256 of
every decoded frame in every format as well: 0.47 ms a 640x512 frame, three times a frame with
the default formats, a third of what the archiver cost beyond the formats' own work (BLAKE3 would
still cost 0.065 ms each). On that same read of the source the pass now also takes an xxh3-128
digest (0.007 ms), and the read-back compares with that. Both digests come from
the same bytes in memory, so a copy that matches one matches the other but for an accidental
128-bit collision; no adversary stands between a writer and its own read-back.

Where the manifest's hashes were kept from an earlier run (a format added later), the source may
have rotted since, so the read-back goes on comparing with the manifest's digests: no xxh3 digest
is taken from a source that is no longer the evidence.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import xxhash

from thermcap.archive.manifest import FrameProof, frame_proof
from thermcap.archive.manifest_types import FramesBlock
from thermcap.recorder.storage.digest import frame_bytes

__all__ = ["ReadBack", "frame_xxh3"]


def frame_xxh3(pixels: np.ndarray) -> bytes:
    """xxh3-128 of the same bytes ``frame_digest`` covers."""
    return xxhash.xxh3_128_digest(frame_bytes(pixels))


@dataclass(frozen=True)
class ReadBack:
    """Per frame what a copy must give back: ``frames`` (the manifest's block: digests of pixels
    and sidecars, times) and, when this run's source pass took them, the xxh3-128 digests of the
    same pixels."""

    frames: FramesBlock
    xxh3: list[bytes] | None = None

    @property
    def proof(self) -> FrameProof:
        return frame_proof(self.frames)

    @property
    def pixel_digest(self) -> tuple[str, Callable[[np.ndarray], str | bytes], list[str] | list[bytes]]:
        """(the digest's name, the function, what each frame's must equal)."""
        proof = self.proof
        if self.xxh3 is not None and len(self.xxh3) == len(proof.pixels):
            return "xxh3-128", frame_xxh3, self.xxh3
        return proof.name, proof.of_pixels, proof.pixels
