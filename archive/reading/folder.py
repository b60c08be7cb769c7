"""A session folder's frames, read where they lie and written nowhere.

``thermcap.open(folder)`` and ``thermcap cut`` read a session on this machine through here: the
frames numbered as the index numbers them (``numbering``), each frame's copies listed (the MCAP
segment that holds it, every archive format on disk) and read through the one checked path
(``copies.read_verified``). Nothing is written: no index, no cache file, no lock; a read-only
share or a copy on a write-protected disk reads the same. Nothing here needs the server's
packages (FastAPI, SQLAlchemy).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.archive.codecs import get_codec
from thermcap.archive.exceptions import FrameNotFound
from thermcap.archive.formats import get_format
from thermcap.archive.formats.base import MCAP_SOURCE_COST, locate, read_cost
from thermcap.archive.manifest import record_digest
from thermcap.archive.reading.copies import (
    Copy,
    DamageLog,
    Part,
    counts_of,
    in_read_order,
    read_verified,
    sidecar_of,
    unoffered,
    wanted,
)
from thermcap.archive.reading.frame_table import FrameTable
from thermcap.archive.reading.mcap_frames import McapFrames
from thermcap.archive.reading.numbering import NumberedFrames, frame_table, number_frames, verified_copies
from thermcap.archive.reading.zip_directory import ZIPPED_FORMATS, ZipIndexCache
from thermcap.recorder.storage.layout import SessionLayout

__all__ = ["FolderFrames"]

class FolderFrames:
    """Frame ``i``'s counts and sidecar, from the first copy in the folder that verifies."""

    def __init__(self, session_dir: Path, session_id: str, damage: DamageLog | None = None) -> None:
        self.dir, self.session_id = Path(session_dir), session_id
        self.layout = SessionLayout.of(self.dir)
        self.problems: list[str] = []  # what could not be read, as `thermcap index` would say it
        self.numbered: NumberedFrames = number_frames(self.dir, self.problems)
        self.damage = damage or DamageLog()
        self._mcap = McapFrames()
        self._zips = ZipIndexCache()

    def __len__(self) -> int:
        return len(self.numbered)

    @cached_property
    def table(self) -> FrameTable:
        return frame_table(self.session_id, self.numbered)

    def pixels(self, index: int) -> np.ndarray:
        return counts_of(self._read(index, "pixels"))

    def sidecar(self, index: int) -> dict[str, Any]:
        return sidecar_of(self._read(index, "sidecar"))

    def _read(self, index: int, part: Part) -> Any:
        n = len(self.numbered)
        if not 0 <= index < n:
            raise FrameNotFound(f"frame {index}: session {self.session_id!r} has {n} frames")
        proof = self.numbered.proof
        return read_verified(self.copies(index), part, session_id=self.session_id, frame=index,
                             want=wanted(proof, index, part), hash_name=proof.name, damage=self.damage,
                             where=str(self.dir))

    def copies(self, index: int) -> list[Copy]:
        """Every copy of frame ``index`` in the folder, cheapest first."""
        copies: list[Copy] = []
        segment = self.numbered.segments[index] if index < len(self.numbered.segments) else None
        if segment:
            path, log_time = self.dir / segment, self.numbered.times[index]
            copies.append(Copy(f"mcap:{segment}", MCAP_SOURCE_COST,
                               lambda part: self._from_mcap(path, log_time, part)))
        manifest = self.numbered.manifest or {}
        in_archive = len((manifest.get("frames") or {}).get("timestamps_ns") or [])
        has_digest = bool(wanted(self.numbered.proof, index, "pixels"))
        offered = verified_copies(manifest)
        for fmt, entry in (manifest.get("formats") or {}).items():
            files = entry.get("files") or []
            if index >= in_archive or not files or not self.layout.format_dir(fmt).is_dir():
                continue
            if fmt not in offered and not has_digest:
                continue  # an unverified copy with nothing to check it against
            cost = read_cost(fmt) if fmt in offered else unoffered(read_cost(fmt))
            rel, _ = locate(files, index)
            copies.append(Copy(f"{fmt}:{rel}", cost, self._archive_reader(fmt, entry, index)))
        return in_read_order(copies)

    def _from_mcap(self, path: Path, log_time: int, part: Part) -> Any:
        if not path.is_file():
            raise FrameNotFound(f"{path.name} is not on disk")
        pixels, sidecar = self._mcap.frame(path, log_time)
        if pixels is None:
            raise FrameNotFound(f"no frame at {log_time} in {path.name}")
        return pixels if part == "pixels" else (sidecar or b"")

    def _archive_reader(self, fmt: str, entry: dict[str, Any], index: int) -> Callable[[Part], Any]:
        files = entry["files"]
        folder = self.layout.format_dir(fmt)
        if fmt in ZIPPED_FORMATS:
            def read_entry(part: Part) -> Any:
                rel, k = locate(files, index)
                record = next(r for r in files if r["path"] == rel)
                with open(folder / rel, "rb") as f:
                    fd = f.fileno()

                    def read(a: int, b: int) -> bytes:
                        return os.pread(fd, b - a, a)

                    entries = self._zips.get(str(folder / rel), os.fstat(fd).st_size, read,
                                             str((record_digest(record) or ("", ""))[1]))
                    blob = entries.blob(k)
                    if part == "sidecar":
                        return read(blob["sidecar_offset"], blob["sidecar_offset"] + blob["sidecar_length"])
                    return get_codec(entry.get("config", {}).get("codec") or fmt).decode(
                        read(blob["offset"], blob["offset"] + blob["length"]))
            return read_entry

        def read_frame(part: Part) -> Any:
            def open_file(rel: str) -> Any:
                return open(folder / rel, "rb")

            frame = get_format(entry.get("config") or fmt).read_frame(open_file, files, index)
            return frame.pixels if part == "pixels" else frame.sidecar
        return read_frame
