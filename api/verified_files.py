"""Whole archive files are checked against the manifest's digest before they are served.

A download's ETag is the manifest's hash, a promise about the bytes; a file damaged on disk
since it was archived must not be sent under it. Before a download starts, its size is compared
and (on local disk) its hash, kept per (size, mtime, inode) so an unchanged file is not read
twice. That key cannot see a file that rots in place (one byte changed, same size, inode and
mtime), nor an object in a bucket changed behind the store's back, so every whole-file download
is also hashed as it is sent (``verified_stream``), its last piece held back until the hash
matches: a damaged file never arrives whole under the manifest's ETag, and it is reported.
"""

from __future__ import annotations

import threading
from collections.abc import AsyncIterator, Callable
from pathlib import Path

from thermcap.api.storage import BlobStore
from thermcap.archive.manifest import file_digest, new_hasher

__all__ = ["DamagedWhileServing", "FileVerifier", "verified_stream"]


class DamagedWhileServing(Exception):
    """Raised inside a response body: the server closes the connection before the last bytes."""


async def verified_stream(pieces: AsyncIterator[bytes], named: tuple[str, str],
                          on_damage: Callable[[str], None]) -> AsyncIterator[bytes]:
    """``pieces`` passed on, hashed as they go; the last one is sent only if the whole hashes
    to ``named`` (hash, hex digest), otherwise ``on_damage`` is told and the body ends short (the
    client sees an incomplete transfer, never a complete file with the wrong bytes)."""
    name, want = named
    h = new_hasher(name)
    held: bytes | None = None
    async for piece in pieces:
        if held is not None:
            yield held
        h.update(piece)
        held = piece
    if h.hexdigest() != want:
        on_damage(f"{name} differs from the manifest (found while sending it)")
        raise DamagedWhileServing(f"the file's bytes differ from the manifest's {name}")
    if held is not None:
        yield held


class FileVerifier:
    def __init__(self, store: BlobStore, root: Path, keep: int = 4096) -> None:
        self.store, self.root, self.keep = store, Path(root), keep
        self._known: dict[str, tuple[tuple[int, int, int, str], str]] = {}
        self._lock = threading.Lock()

    def forget(self, key: str) -> None:
        """Hash the file again next time (it was found damaged while it was served)."""
        with self._lock:
            self._known.pop(key, None)

    def problem(self, key: str, named: tuple[str, str], size: int) -> str | None:
        """Why the stored file is not the archived one (``named``: the manifest's hash and hex
        digest of it), or None when it is."""
        name, want = named
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
        stamp = (st.st_size, st.st_mtime_ns, st.st_ino, name)
        with self._lock:
            known = self._known.get(key)
        if known is None or known[0] != stamp:
            known = (stamp, file_digest(path, name))
            with self._lock:
                if len(self._known) >= self.keep:
                    self._known.pop(next(iter(self._known)))
                self._known[key] = known
        return None if known[1] == want else f"{name} differs from the manifest"
