"""The sidecars of an ``hdf5`` archive read straight from HDF5's global heap, with every length
and offset checked, so damaged bytes can only fail, never hang.

The sidecars are a variable-length UTF-8 dataset: each element is a 16-byte descriptor (the
string's length, the address of a global heap collection, the object's index in it) and the
strings live in those collections (``GCOL``). HDF5's own read of a collection whose bytes are
damaged can loop for good inside the library, holding h5py's global lock, so that every other
HDF5 read of the process waits too. Here a collection is parsed in Python, bounded by its
declared size, each object's size checked against what is left: a damaged one raises
``ArchiveError``. The strings are then checked against the manifest's sidecar hashes, like any
other copy.

Layout, from the HDF5 File Format Specification (III.E, Global Heap; VI, variable-length
datatypes): a collection is ``"GCOL"``, a version byte (1), three reserved bytes, the
collection's size (a "length", 8 bytes here); then objects, each a 2-byte index (0: the free
space, which ends the list), a 2-byte reference count, 4 reserved bytes, its size (8 bytes)
and its data, padded to a multiple of 8.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from thermcap.archive.exceptions import ArchiveError

__all__ = ["HeapStrings", "heap_strings"]

_DESCRIPTOR = struct.Struct("<IQI")  # sequence length, collection address, object index
_COLLECTION = struct.Struct("<4sB3xQ")
_OBJECT = struct.Struct("<HH4xQ")
#: HDF5 writes collections of 4 KiB and more; one holding a single huge string is its size
MAX_COLLECTION = 256 << 20

ReadAt = Callable[[int, int], bytes]


def heap_strings(dataset: Any) -> tuple[int, int] | None:
    """(file address of the descriptors, element count) of a contiguous vlen-string dataset in a
    file whose addresses and lengths are 8 bytes; None for any other (read it through h5py)."""
    try:
        offset = dataset.id.get_offset()
        sizes = dataset.file.id.get_create_plist().get_sizes()
    except Exception:
        return None
    if offset is None or tuple(sizes) != (8, 8):
        return None
    return int(offset), int(dataset.shape[0])


class HeapStrings:
    """Strings ``i..j`` of a vlen dataset whose descriptors start at ``offset``; collections are
    kept while reading on (consecutive strings share them)."""

    def __init__(self, read_at: ReadAt, offset: int, count: int, where: str) -> None:
        self.read_at, self.offset, self.count, self.where = read_at, offset, count, where
        self._collections: dict[int, dict[int, bytes]] = {}

    def get(self, start: int, stop: int) -> list[bytes]:
        if not 0 <= start <= stop <= self.count:
            raise ArchiveError(f"{self.where}: sidecars {start}..{stop} of {self.count}")
        raw = self.read_at(self.offset + 16 * start, 16 * (stop - start))
        if len(raw) != 16 * (stop - start):
            raise ArchiveError(f"{self.where}: the sidecars' descriptors are cut short")
        out = []
        for k in range(stop - start):
            length, address, index = _DESCRIPTOR.unpack_from(raw, 16 * k)
            objects = self._collection(address)
            data = objects.get(index)
            if data is None or len(data) < length:
                raise ArchiveError(f"{self.where}: sidecar {start + k}: object {index} of the heap collection at "
                                   f"{address} is missing or short")
            out.append(data[:length])
        if len(self._collections) > 8:  # read on in order: the old ones are not met again
            for key in list(self._collections)[:-4]:
                del self._collections[key]
        return out

    def _collection(self, address: int) -> dict[int, bytes]:
        if address in self._collections:
            return self._collections[address]
        head = self.read_at(address, _COLLECTION.size)
        if len(head) != _COLLECTION.size:
            raise ArchiveError(f"{self.where}: heap collection at {address} is past the end of the file")
        signature, version, size = _COLLECTION.unpack(head)
        if signature != b"GCOL" or version != 1 or not _COLLECTION.size <= size <= MAX_COLLECTION:
            raise ArchiveError(f"{self.where}: no heap collection at {address} (damaged)")
        body = self.read_at(address, size)
        if len(body) != size:
            raise ArchiveError(f"{self.where}: heap collection at {address} is cut short")
        objects: dict[int, bytes] = {}
        pos = _COLLECTION.size
        while pos + _OBJECT.size <= size:  # every turn moves on by at least 16 bytes
            index, _refs, length = _OBJECT.unpack_from(body, pos)
            if index == 0:  # the free space: no object after it
                break
            start = pos + _OBJECT.size
            if length > size - start:
                raise ArchiveError(f"{self.where}: heap object {index} at {address} runs past its collection")
            objects[index] = body[start:start + length]
            pos = start + ((length + 7) & ~7)
        self._collections[address] = objects
        return objects
