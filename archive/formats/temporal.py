"""``tpred``: the temporal codec (``archive.codecs.tpred.codec``) in one stored ZIP per segment.

Each frame is ``thermal_<time>_<sensor>_<range>.tpf`` (one tpred record) with its ICD ``.json``
sidecar beside it, as ``png16`` lays its frames out. Every segment starts a new sequence, so its
first frame is a key frame and frame ``k`` of a file decodes from the key at
``k - k % key_interval`` in at most ``key_interval`` steps: ``read_frame`` reads only those
members (ranged reads on an object store).
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.archive.codecs.tpred.codec import (
    BITSTREAM_VERSION,
    KEY,
    MAGICS,
    TpredError,
    decode_gops,
    encode_gops,
    parse_header,
)
from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats.base import ArchiveContext, ArchiveFormat, DecodedFrame, FileRecord, locate
from thermcap.archive.formats.zipped import _time_from_name, write_zip_segments
from thermcap.recorder.storage.reader import SessionFrame

__all__ = ["TemporalFrames"]

EXT = ".tpf"


class TemporalFrames(ArchiveFormat):
    format_id = "tpred"
    description = "one stored ZIP per segment of temporally predicted frames (tpred) + ICD JSON sidecars"

    def __init__(self, window: int = 16, key_interval: int = 64, max_shift: int = 32,
                 bitstream: int = BITSTREAM_VERSION) -> None:
        if bitstream not in MAGICS:
            raise ArchiveError(f"tpred bitstream version {bitstream} is not one this thermcap reads "
                               f"({', '.join(map(str, sorted(MAGICS)))})")
        self.window, self.key_interval, self.max_shift, self.bitstream = window, key_interval, max_shift, bitstream

    def get_config(self) -> dict[str, Any]:
        # the version written, so each archive's manifest says which one it holds
        return {"id": self.format_id, "window": self.window, "key_interval": self.key_interval,
                "max_shift": self.max_shift, "bitstream": self.bitstream}

    def write(self, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext) -> list[FileRecord]:
        def sequence(run: Iterator[SessionFrame]) -> Iterator[tuple[SessionFrame, bytes]]:
            # every segment starts a key; its GOPs are encoded on the archive's threads at once
            return encode_gops(run, lambda frame: np.asarray(frame.pixels), workers=ctx.workers, window=self.window,
                               key_interval=self.key_interval, max_shift=self.max_shift, bitstream=self.bitstream)

        return write_zip_segments(frames, out_dir, ctx, EXT, sequence)

    def read(self, out_dir: Path, files: list[str], workers: int = 2) -> Iterator[DecodedFrame]:
        """Every frame, a GOP on each of ``workers`` threads (verification decodes every frame)."""
        for rel in files:
            path = out_dir / rel
            try:
                with zipfile.ZipFile(path) as zf:
                    yield from _decode_run(zf, 0, None, workers=workers)
            except (zipfile.BadZipFile, OSError) as exc:
                raise ArchiveError(f"{path}: not a readable ZIP ({exc})") from exc

    def read_frame(self, open_file: Any, files: list[dict[str, Any]], index: int) -> DecodedFrame:
        rel, k = locate(files, index)
        with open_file(rel) as fh:
            try:
                with zipfile.ZipFile(fh) as zf:
                    members = [i for i in zf.infolist() if i.filename.endswith(EXT)]
                    key = k - k % self.key_interval
                    while key > 0 and parse_header(zf.read(members[key])).kind != KEY:
                        key -= 1  # a file written with another interval: walk back to its key
                    *_, last = _decode_run(zf, key, k + 1)
                    return last
            except (zipfile.BadZipFile, OSError, IndexError, TpredError) as exc:
                raise ArchiveError(f"{rel}: cannot read frame {k} ({exc})") from exc


def _decode_run(zf: zipfile.ZipFile, start: int, stop: int | None, workers: int = 1) -> Iterator[DecodedFrame]:
    names = set(zf.namelist())
    members = [i for i in zf.infolist() if i.filename.endswith(EXT)][start:stop]
    try:
        for info, pixels in decode_gops(members, zf.read, workers=workers, name=lambda i: i.filename):
            base = info.filename[: -len(EXT)]
            sidecar = zf.read(base + ".json") if base + ".json" in names else b""
            yield DecodedFrame(pixels, sidecar, _time_from_name(base))
    except TpredError as exc:
        raise ArchiveError(str(exc)) from None
