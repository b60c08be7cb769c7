"""A file read by offset, for the SEQ/CSQ walker: bytes come from ``os.pread``, never from a
mapping of the file.

Why not ``mmap``: a mapped page the kernel cannot fill (the file cut by another process, a copy
overwritten in the inbox, an SD card pulled, a network share's read error) is not an error but
the signal SIGBUS, which ends the whole process: ``thermcap import`` or the inbox's watcher
died without naming the file, and without reporting the frames it had already written. Here a
short or failed read raises ``ImportFileError`` naming the file, the offset and what the file
holds now. Memory stays what it was with the mapping: one image at a time (a walker asks for
an image's extent in one read), and no pages of the file are held after it.
"""

from __future__ import annotations

import os

from thermcap.recorder.importers.base import ImportFileError

__all__ = ["FileView"]


class FileView:
    """The slices and ``len`` of ``bytes`` over an open file's first ``size`` bytes
    (its size when opened: a file that shrinks after that fails a read, by name)."""

    def __init__(self, path: str, fd: int) -> None:
        self.path = path
        self._fd = fd
        self._size = os.fstat(fd).st_size

    def __len__(self) -> int:
        return self._size

    def __getitem__(self, key: slice) -> bytes:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("FileView takes contiguous slices only")
        start, stop, _ = key.indices(self._size)
        return self._read(start, max(0, stop - start))

    def _read(self, offset: int, length: int) -> bytes:
        """``length`` bytes at ``offset``, read until they are all there (a network file system may
        return fewer than asked) or the file ends."""
        parts, got = [], 0
        while got < length:
            try:
                part = os.pread(self._fd, length - got, offset + got)
            except OSError as exc:
                raise ImportFileError(f"{self.path}: cannot read {length} bytes at byte {offset} "
                                      f"({exc.strerror or exc})") from None
            if not part:
                break
            parts.append(part)
            got += len(part)
        data = parts[0] if len(parts) == 1 else b"".join(parts)
        if len(data) != length:
            now = _size_now(self._fd)
            raise ImportFileError(f"{self.path}: the file changed while it was read: {length} bytes at byte {offset} "
                                  f"gave {len(data)}; it was {self._size} bytes when opened"
                                  + (f" and is {now} now" if now is not None else ""))
        return data


def _size_now(fd: int) -> int | None:
    try:
        return os.fstat(fd).st_size
    except OSError:
        return None
