"""Per-frame images in one uncompressed ZIP per segment: ``png16`` (and ``jxl``, ``htj2k``).

Each frame is ``thermal_<time>_<sensor>_<range>.<ext>`` with its ICD ``.json`` sidecar beside
it, so unzipping gives exactly the ICD's file pairs. The ZIP is stored (no deflate: the images
are already compressed), so any frame is one ranged read once the central directory is known.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from thermcap.archive.codecs import FrameCodec, get_codec
from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats.base import (
    ArchiveContext,
    ArchiveFormat,
    DecodedFrame,
    FileRecord,
    frame_name,
    group_by_segment,
    locate,
    ordered_map,
    sidecar_text,
)
from thermcap.recorder.storage.reader import SessionFrame

__all__ = ["ZippedFrames", "write_zip_segments"]


class ZippedFrames(ArchiveFormat):
    description = "one stored ZIP per segment of per-frame images + ICD JSON sidecars"

    def __init__(self, codec: FrameCodec, format_id: str | None = None) -> None:
        self.codec = codec
        self.format_id = format_id or codec.codec_id

    def get_config(self) -> dict:
        return {"id": self.format_id, "codec": self.codec.get_config()}

    def write(self, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext) -> list[FileRecord]:
        codec = self.codec

        def encode(frame: SessionFrame) -> tuple[SessionFrame, bytes]:
            return frame, codec.encode(np.asarray(frame.pixels))

        return write_zip_segments(frames, out_dir, ctx, codec.extension,
                                  lambda run: ordered_map(encode, run, ctx.workers))

    def read(self, out_dir: Path, files: list[str], workers: int = 2) -> Iterator[DecodedFrame]:
        ext, codec = self.codec.extension, self.codec
        for rel in files:
            path = out_dir / rel
            try:
                with zipfile.ZipFile(path) as zf:
                    # the ZIP is read here, in order; the images decode on ``workers`` threads
                    # (the codecs release the GIL): alone on two cores, verifying takes half the time
                    for pixels, sidecar, base in ordered_map(lambda e: (codec.decode(e[0]), e[1], e[2]),
                                                             _members(zf, ext), workers):
                        yield DecodedFrame(pixels, sidecar, _time_from_name(base))
            except (zipfile.BadZipFile, OSError) as exc:
                raise ArchiveError(f"{path}: not a readable ZIP ({exc})") from exc


    def read_frame(self, open_file, files: list[dict], index: int) -> DecodedFrame:
        rel, k = locate(files, index)
        ext = self.codec.extension
        with open_file(rel) as fh:
            try:
                with zipfile.ZipFile(fh) as zf:
                    images = [i for i in zf.infolist() if i.filename.endswith(ext)]
                    base = images[k].filename[: -len(ext)]
                    names = set(zf.namelist())
                    sidecar = zf.read(base + ".json") if base + ".json" in names else b""
                    return DecodedFrame(self.codec.decode(zf.read(images[k])), sidecar, _time_from_name(base))
            except (zipfile.BadZipFile, OSError, IndexError) as exc:
                raise ArchiveError(f"{rel}: cannot read frame {k} ({exc})") from exc


def _members(zf: zipfile.ZipFile, ext: str) -> Iterator[tuple[bytes, bytes, str]]:
    """(image bytes, sidecar bytes, base name) of each image in the ZIP, in order."""
    names = set(zf.namelist())
    for info in zf.infolist():
        if info.filename.endswith(ext):
            base = info.filename[: -len(ext)]
            yield zf.read(info), zf.read(base + ".json") if base + ".json" in names else b"", base


def write_zip_segments(frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext, ext: str,
                       encoded: Callable[[Iterator[SessionFrame]], Iterable[tuple[SessionFrame, bytes]]],
                       ) -> list[FileRecord]:
    """One stored ZIP per segment of ICD pairs ``<frame name><ext>`` + ``.json``; ``encoded``
    turns a segment's frames into (frame, bytes) in order (on a pool, or one sequence)."""
    records = []
    for segment, run in group_by_segment(frames):
        rel = Path(segment).stem + ".zip"
        n = 0
        with zipfile.ZipFile(out_dir / rel, "x", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for frame, data in encoded(run):
                name = frame_name(ctx, frame)
                zf.writestr(_info(name + ext, frame.log_time), data)
                zf.writestr(_info(name + ".json", frame.log_time), sidecar_text(frame))
                n += 1
                if ctx.on_frame:
                    ctx.on_frame()
        records.append(FileRecord(rel, n))
    return records


def _time_from_name(base: str) -> int | None:
    from thermcap.recorder.icd.names import parse_name

    try:
        return parse_name(base).timestamp_ns
    except (ValueError, AttributeError):
        return None


def _info(name: str, log_time: int) -> zipfile.ZipInfo:
    import time

    info = zipfile.ZipInfo(name, date_time=time.gmtime(max(log_time // 1_000_000_000, 315532800))[:6])
    info.compress_type = zipfile.ZIP_STORED
    info.external_attr = 0o644 << 16
    return info


def zipped_factory(format_id: str, **defaults):
    """A registry factory: ``get_format({"id": "png16", "codec": {...}})`` or ``get_format("png16")``."""

    def make(codec: dict | None = None, **codec_kwargs) -> ZippedFrames:
        config = dict(codec) if codec else {"id": format_id, **defaults, **codec_kwargs}
        return ZippedFrames(get_codec(config), format_id)

    return make
