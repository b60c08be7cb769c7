"""Whole archive files are checked against the manifest's sha256 before they are served.

A download's ETag is the manifest's hash, a promise about the bytes; a file damaged on disk
since it was archived must not be sent under it. Hashing a file costs one read of it, so the
result is kept per (size, mtime, inode): a file is hashed again only when it changes. Objects in
an S3-compatible store were written create-only and are checked by the store's own checksums
and by ``thermcap scrub``; here their size is compared.
"""

from __future__ import annotations

import threading
from pathlib import Path

from api.storage import BlobStore
from archive.manifest import file_sha256

__all__ = ["FileVerifier"]


class FileVerifier:
    def __init__(self, store: BlobStore, root: Path, keep: int = 4096) -> None:
        self.store, self.root, self.keep = store, Path(root), keep
        self._known: dict[str, tuple[tuple[int, int, int], str]] = {}
        self._lock = threading.Lock()

    def problem(self, key: str, sha256: str, size: int) -> str | None:
        """Why the stored file is not the archived one, or None when it is."""
        if self.store.kind != "local":
            head = self.store.head(key)
            if head is None:
                return "missing from the store"
            return None if head["size"] == size else f"{head['size']} bytes in the store, {size} archived"
        path = self.root / key
        try:
            st = path.stat()
        except FileNotFoundError:
            return "missing"
        if st.st_size != size:
            return f"{st.st_size} bytes on disk, {size} archived"
        stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
        with self._lock:
            known = self._known.get(key)
        if known is None or known[0] != stamp:
            known = (stamp, file_sha256(path))
            with self._lock:
                if len(self._known) >= self.keep:
                    self._known.pop(next(iter(self._known)))
                self._known[key] = known
        return None if known[1] == sha256 else "sha256 differs from the manifest"
