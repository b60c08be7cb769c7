"""The project's two hashes, in one place for every package: a file's sha256 (the archive's
manifest, sync's journal and targets, the cloud's receipts, the inbox) and a frame's (the
manifest, the importers' reports, the inspection report)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

__all__ = ["file_sha256", "frame_bytes", "frame_sha256"]


def file_sha256(path: str | Path) -> str:
    """hashlib's own file loop: it reads into one reused 256 KB buffer, which stays in cache,
    where 1 MB reads made a new bytes object each (0.58 against 0.62-0.86 CPU ms a MB here)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def frame_bytes(pixels: np.ndarray) -> memoryview:
    """The bytes every frame digest covers: uint16 LE, row-major (a copy only where the array is
    not already laid out so)."""
    return np.ascontiguousarray(pixels, dtype="<u2").data.cast("B")


def frame_sha256(pixels: np.ndarray) -> str:
    """The project-wide frame hash: sha256 of the uint16 LE row-major bytes."""
    return hashlib.sha256(frame_bytes(pixels)).hexdigest()
