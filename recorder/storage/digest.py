"""The sha256 of a file, read in 1 MiB blocks: the one way every part of thermcap hashes a file
(the archive's manifest, sync's journal and targets, the cloud's receipts)."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["file_sha256"]


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            h.update(block)
    return h.hexdigest()
