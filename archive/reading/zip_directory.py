"""Where each frame sits in a stored-ZIP archive, from the ZIP's own central directory.

Why: the index used to keep a row per frame per format (``frame_blobs``) for this. One
camera-hour at 60 fps was a quarter of a million rows per format, and a fleet's index would reach
billions. The archive already says it all: a ZIP's central directory lists each entry's local
header offset, size and CRC-32. It is read once per file, with two ranged reads (the end record,
then the directory) from the local disk or the bucket, and kept as five small arrays.

An entry's data starts after its local header: 30 bytes, its name, and its local extra field.
The writer (``zipfile``'s ``writestr``, stored, no forced ZIP64) gives an entry the same extra in
both headers, apart from the ZIP64 field, which only the directory carries. That is checked
against the real local headers of the first and last entries. A file that breaks it has every
local header read instead. The CRC-32 is checked again on every read before bytes go out.
"""

from __future__ import annotations

import os
import struct
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["ZIPPED_FORMATS", "ZipEntries", "ZipIndexCache", "read_zip_entries", "read_zip_file"]

#: The archive formats whose objects are zips of one file a frame, read by offset from a zip index.
ZIPPED_FORMATS = ("png16", "jxl", "htj2k", "jpegls")

_EOCD = struct.Struct("<4sHHHHIIH")
_ZIP64_LOCATOR = struct.Struct("<4sIQI")
_ZIP64_EOCD = struct.Struct("<4sQHHIIQQQQ")
_CENTRAL = struct.Struct("<4sHHHHHHIIIHHHHHII")
_LOCAL = struct.Struct("<4sHHHHHIIIHH")

ReadRange = Callable[[int, int], bytes]  # [start, end) of the file


@dataclass(frozen=True)
class ZipEntries:
    """One archive file's frames: image entry k and its sidecar entry, in file order."""

    offset: np.ndarray  # int64: where image k's bytes start
    length: np.ndarray
    crc32: np.ndarray
    sidecar_offset: np.ndarray
    sidecar_length: np.ndarray

    @property
    def frames(self) -> int:
        return len(self.offset)

    def blob(self, k: int) -> dict[str, int]:
        return {"offset": int(self.offset[k]), "length": int(self.length[k]), "crc32": int(self.crc32[k]),
                "sidecar_offset": int(self.sidecar_offset[k]), "sidecar_length": int(self.sidecar_length[k])}


def _directory(read: ReadRange, size: int, name: str) -> tuple[int, int, int]:
    """(entries, directory offset, directory size) from the end records."""
    tail_start = max(0, size - (_EOCD.size + 0xFFFF))
    tail = read(tail_start, size)
    at = tail.rfind(b"PK\x05\x06")
    if at < 0:
        raise ValueError(f"{name}: no ZIP end of central directory record")
    _, _, _, _, total, cd_size, cd_offset, _ = _EOCD.unpack_from(tail, at)
    if total == 0xFFFF or cd_size == 0xFFFFFFFF or cd_offset == 0xFFFFFFFF:
        loc = at - _ZIP64_LOCATOR.size
        if loc < 0 or tail[loc:loc + 4] != b"PK\x06\x07":
            raise ValueError(f"{name}: a ZIP64 archive without its locator")
        _, _, rec_offset, _ = _ZIP64_LOCATOR.unpack_from(tail, loc)
        rec = read(rec_offset, rec_offset + _ZIP64_EOCD.size)
        sig, _, _, _, _, _, _, total, cd_size, cd_offset = _ZIP64_EOCD.unpack(rec)
        if sig != b"PK\x06\x06":
            raise ValueError(f"{name}: bad ZIP64 end of central directory record")
    return total, cd_offset, cd_size


def _zip64(extra: bytes, sizes: list[int], header_offset: int) -> tuple[int, int, int, int]:
    """(compressed size, header offset, the ZIP64 field's length in the extra) for one entry."""
    pos = 0
    while pos + 4 <= len(extra):
        tag, n = struct.unpack_from("<HH", extra, pos)
        if tag == 1:
            vals = list(struct.unpack_from(f"<{n // 8}Q", extra, pos + 4))
            usize, csize = sizes
            if usize == 0xFFFFFFFF:
                usize = vals.pop(0)
            if csize == 0xFFFFFFFF:
                csize = vals.pop(0)
            if header_offset == 0xFFFFFFFF:
                header_offset = vals.pop(0)
            return csize, header_offset, 4 + n, usize
        pos += 4 + n
    return sizes[1], header_offset, 0, sizes[0]


def read_zip_entries(read: ReadRange, size: int, name: str) -> ZipEntries:
    total, cd_offset, cd_size = _directory(read, size, name)
    cd = read(cd_offset, cd_offset + cd_size)
    starts, lengths, crcs, names, local_extra, headers = [], [], [], [], [], []
    pos = 0
    for _ in range(total):
        if cd[pos:pos + 4] != b"PK\x01\x02":
            raise ValueError(f"{name}: bad central directory entry at {cd_offset + pos}")
        (_, _, _, _, method, _, _, crc, csize, usize, nlen, elen, clen, _, _, _, hoff) = _CENTRAL.unpack_from(cd, pos)
        entry_name = cd[pos + _CENTRAL.size:pos + _CENTRAL.size + nlen]
        extra = cd[pos + _CENTRAL.size + nlen:pos + _CENTRAL.size + nlen + elen]
        csize, hoff, z64, usize = _zip64(extra, [usize, csize], hoff)
        if method != 0 or csize != usize:
            raise ValueError(f"{name}: entry {entry_name!r} is compressed; archives are stored ZIPs")
        headers.append(hoff)
        names.append(entry_name)
        local_extra.append(elen - z64)
        starts.append(hoff + _LOCAL.size + nlen + elen - z64)
        lengths.append(csize)
        crcs.append(crc)
        pos += _CENTRAL.size + nlen + elen + clen
    if total and not all(_local_header_agrees(read, headers[k], names[k], local_extra[k]) for k in {0, total - 1}):
        starts = [_data_start(read, h, name) for h in headers]  # another writer's layout: read them all
    if total % 2 or any(n.endswith(b".json") for n in names[::2]) or not all(n.endswith(b".json") for n in names[1::2]):
        raise ValueError(f"{name}: not a thermcap archive ZIP (image and .json entries in pairs)")
    arr = np.asarray(starts, np.int64), np.asarray(lengths, np.int64), np.asarray(crcs, np.int64)
    return ZipEntries(arr[0][0::2], arr[1][0::2], arr[2][0::2], arr[0][1::2], arr[1][1::2])


def _local_header_agrees(read: ReadRange, header_offset: int, entry_name: bytes, extra_len: int) -> bool:
    head = read(header_offset, header_offset + _LOCAL.size + len(entry_name))
    sig, *_, nlen, elen = _LOCAL.unpack_from(head)
    return sig == b"PK\x03\x04" and nlen == len(entry_name) and elen == extra_len \
        and head[_LOCAL.size:] == entry_name


def _data_start(read: ReadRange, header_offset: int, name: str) -> int:
    head = read(header_offset, header_offset + _LOCAL.size)
    sig, *_, nlen, elen = _LOCAL.unpack(head)
    if sig != b"PK\x03\x04":
        raise ValueError(f"{name}: bad local header at {header_offset}")
    return header_offset + _LOCAL.size + nlen + elen


def read_zip_file(path: Path) -> ZipEntries:
    """The entries of an archive ZIP on local disk (the indexer reads its sidecars by them)."""
    with open(path, "rb") as f:
        fd = f.fileno()
        return read_zip_entries(lambda a, b: os.pread(fd, b - a, a), os.fstat(fd).st_size, str(path))


class ZipIndexCache:
    """Entries per archive file, bounded. Keyed by the file's key, size and digest (from the
    manifest): a copy that ``scrub --repair`` rewrote is another entry, even at the same size."""

    def __init__(self, keep: int = 256) -> None:
        self._entries: OrderedDict[tuple[str, int, str], ZipEntries] = OrderedDict()
        self._keep = keep
        self._lock = threading.Lock()

    def get(self, key: str, size: int, read: ReadRange, digest: str = "") -> ZipEntries:
        ident = (key, size, digest)
        with self._lock:
            got = self._entries.get(ident)
            if got is not None:
                self._entries.move_to_end(ident)
                return got
        got = read_zip_entries(read, size, key)
        with self._lock:
            self._entries[ident] = got
            while len(self._entries) > self._keep:
                self._entries.popitem(last=False)
        return got
