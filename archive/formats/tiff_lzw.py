"""``tiff-lzw``: one multi-page little-endian TIFF per segment, LZW with horizontal predictor.

Every page carries the ICD's mandatory tags (width, length, 16 bits, photometric BlackIsZero,
strip offsets, one sample, rows per strip, chunky, unsigned) and its frame's sidecar JSON in
ImageDescription. tifffile omits PlanarConfiguration (284) and SampleFormat (339) for one-sample
unsigned images and refuses to add them: their TIFF 6.0 defaults are exactly the ICD's values
(1 = chunky, 1 = unsigned), so every reader sees the same image. Compression is LZW (5), not the
ICD's 1, because this is the archive copy;
``thermcap export --to icd`` writes uncompressed ICD files. The strips (64 rows, so a box of
rows reads one or two of them) are encoded by ``archive.lzw``, libtiff's algorithm compiled,
and handed to tifffile ready; tifffile, libtiff, ImageJ and GDAL all read them.
"""

from __future__ import annotations

import itertools
import mmap
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import imagecodecs
import numpy as np
import tifffile

from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats.base import (
    ArchiveContext,
    ArchiveFormat,
    DecodedFrame,
    FileRecord,
    RowBlock,
    group_by_segment,
    locate,
    ordered_map,
    positions_in,
    sidecar_text,
    time_from_sidecar,
)
from thermcap.archive.lzw import lzw_encode_strips
from thermcap.recorder.storage.reader import SessionFrame

__all__ = ["TiffLzw", "decode_strip", "encode_page", "write_page"]

_BIGTIFF_ABOVE = 3_500_000_000  # classic TIFF offsets are 32-bit
#: A private tag (ASCII) holding the frame's log time in Unix ns, so the time survives apart from
#: the sidecar; archives written before it fall back to the sidecar's capture.timestamp.
LOG_TIME_TAG = 65000


class TiffLzw(ArchiveFormat):
    format_id = "tiff-lzw"
    description = "one multi-page LZW+predictor TIFF per segment, sidecar JSON per page"

    def __init__(self, rowsperstrip: int = 64) -> None:
        self.rowsperstrip = rowsperstrip

    def get_config(self) -> dict:
        return {"id": self.format_id, "rowsperstrip": self.rowsperstrip}

    def write(self, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext) -> list[FileRecord]:
        records = []
        for segment, run in group_by_segment(frames):
            rel = Path(segment).stem + ".tif"
            n = 0
            big = None
            with open(out_dir / rel, "xb") as fh:
                writer = None
                for frame in run:
                    if writer is None:
                        raw = frame.pixels.nbytes * max(1, ctx.frames_per_segment.get(segment, 1))
                        big = raw > _BIGTIFF_ABOVE
                        writer = tifffile.TiffWriter(fh, byteorder="<", bigtiff=big)
                    write_page(writer, frame.pixels, self.rowsperstrip, description=sidecar_text(frame),
                               metadata=None, software="thermcap",
                               extratags=[(LOG_TIME_TAG, "s", 0, str(frame.log_time), True)])
                    n += 1
                    if ctx.on_frame:
                        ctx.on_frame()
                if writer is not None:
                    writer.close()
            records.append(FileRecord(rel, n))
        return records

    def read(self, out_dir: Path, files: list[str], workers: int = 2) -> Iterator[DecodedFrame]:
        """Every page, in order: its tags (sidecar, time) as tifffile reads them, its pixels as
        libtiff decodes them, up to ``PAGES_PER_CALL`` pages a call on ``workers`` threads (see
        ``_libtiff_pages``)."""
        for rel in files:
            path = out_dir / rel
            try:
                with open(path, "rb") as fh, tifffile.TiffFile(fh) as tif:
                    image = _FileImage(fh.fileno(), os.fstat(fh.fileno()).st_size)
                    try:
                        yield from _libtiff_pages(image, tif, workers)
                    finally:
                        image.close()
            except (tifffile.TiffFileError, imagecodecs.TiffError, OSError, ValueError) as exc:
                raise ArchiveError(f"{path}: not a readable TIFF ({exc})") from exc

    def read_frame(self, open_file, files: list[dict], index: int) -> DecodedFrame:
        """Page k alone: tifffile follows the IFD chain and reads only that page's strips."""
        rel, k = locate(files, index)
        with open_file(rel) as fh:
            try:
                with tifffile.TiffFile(fh) as tif:
                    return _decoded(tif.pages[k])
            except (tifffile.TiffFileError, OSError, ValueError, IndexError) as exc:
                raise ArchiveError(f"{rel}: cannot read page {k} ({exc})") from exc

    def read_rows(self, open_file: Callable[[str], Any], files: list[dict[str, Any]], indices: range,
                  y0: int, y1: int) -> Iterator[RowBlock]:
        """Only the strips holding rows ``y0..y1``: a 40-row box decodes one or two of a
        640x512 frame's eight strips. Strips are undone as the TIFF says (LZW, then the
        horizontal predictor), which is what tifffile itself does for the whole page."""
        first = 0
        for rec in files:
            n = int(rec["frames"])
            wanted = [i - first for i in indices[positions_in(indices, first, first + n)]]
            if wanted:
                with open_file(rec["path"]) as fh:
                    try:
                        with tifffile.TiffFile(fh) as tif:
                            for k in wanted:
                                yield RowBlock(first + k, *_strips(fh, tif.pages[k], y0, y1))
                    except (tifffile.TiffFileError, OSError, ValueError, IndexError) as exc:
                        raise ArchiveError(f"{rec['path']}: cannot read rows {y0}..{y1} ({exc})") from exc
            first += n


def write_page(writer: tifffile.TiffWriter, pixels: np.ndarray, rowsperstrip: int, **tags: Any) -> None:
    """One page as the archive stores it: little-endian uint16, LZW with the horizontal
    predictor, ``rowsperstrip``-row strips encoded by ``encode_page``; ``tags`` go to tifffile.
    Only the byte order is changed: any other dtype is refused by ``encode_page``, never cast."""
    pixels = np.asarray(pixels)
    if pixels.dtype.kind == "u" and pixels.dtype.itemsize == 2:
        pixels = np.ascontiguousarray(pixels, "<u2")
    writer.write(iter(encode_page(pixels, rowsperstrip)), shape=pixels.shape, dtype="<u2", compression="lzw",
                 predictor=True, photometric="minisblack", planarconfig="contig", rowsperstrip=rowsperstrip, **tags)


def encode_page(pixels: np.ndarray, rowsperstrip: int) -> list[bytes]:
    """A page's strips as TIFF stores them with LZW and the horizontal predictor (2): each row
    differenced left to right modulo 2**16, then LZW. tifffile would do the same with
    imagecodecs' encoder; ``archive.lzw`` writes the same kind of stream in two thirds of the
    time, in one call per page on the calling thread."""
    if pixels.ndim != 2 or pixels.dtype != np.dtype("<u2"):
        raise ValueError(f"expected a 2-D little-endian uint16 page, got {pixels.dtype} {pixels.shape}")
    diff = imagecodecs.delta_encode(pixels, axis=-1)
    return lzw_encode_strips(diff, rowsperstrip * pixels.shape[1] * 2)


def _strips(fh: Any, page: Any, y0: int, y1: int) -> tuple[int, np.ndarray]:
    if page.compression != 5 or page.predictor not in (1, 2) or page.dtype != np.uint16 or page.samplesperpixel != 1:
        raise ValueError(f"page {page.index} is not a one-sample uint16 LZW page")
    rps, (h, w) = page.rowsperstrip, page.shape[:2]
    s0, s1 = y0 // rps, (min(y1, h) - 1) // rps + 1
    out = np.empty(((min(s1 * rps, h) - s0 * rps), w), np.uint16)
    for s in range(s0, s1):
        fh.seek(page.dataoffsets[s])
        rows = min(rps, h - s * rps)
        out[(s - s0) * rps:(s - s0) * rps + rows] = decode_strip(fh.read(page.databytecounts[s]), rows, w,
                                                                 page.predictor, f"page {page.index}, strip {s}")
    return s0 * rps, out


def decode_strip(data: bytes, rows: int, width: int, predictor: int, where: str) -> np.ndarray:
    """One LZW strip of uint16 samples undone as the TIFF says: LZW, then the horizontal
    predictor (2) where there is one. What tifffile does for a whole page, for one strip."""
    strip = np.frombuffer(imagecodecs.lzw_decode(data), "<u2")
    if strip.size < rows * width:
        raise ValueError(f"{where}: {strip.size} samples, {rows * width} expected")
    strip = strip[: rows * width].reshape(rows, width)
    return imagecodecs.delta_decode(strip, axis=-1) if predictor == 2 else strip


#: Pages libtiff decodes in one call, at most. Each call walks the IFD chain from the first page
#: to its own (about 2 us a page), so a call a page would cost as much as the decoding by page
#: 1,300 of a 60 s segment; 32 pages make the walk 0.1 ms a page there.
PAGES_PER_CALL = 32
#: ... and no more pages than fit in this many bytes (the first page's size counts for all): a
#: call's pages are held decoded, three calls in flight, so memory stays about 64 MB whatever
#: the sensor (25 pages a call at 640x512, 6 at 1280x1024).
BYTES_PER_CALL = 16 << 20


class _FileImage:
    """A file's bytes at their own offsets, in anonymous memory that reads fill as the pages come,
    for libtiff to decode from as from the file.

    Why not a mapping of the file: libtiff then reads the strips straight from the page cache,
    and a page the disk cannot give back (a bad sector, which ``scrub`` is there to find) or that
    another process cut off meanwhile ends the whole process with SIGBUS, where a read raises
    OSError and the copy is reported damaged. Zero pages cost nothing until written, and each
    batch's strips are given back once decoded (``release``); the IFDs stay, since libtiff walks
    the chain from the first to the page it decodes."""

    def __init__(self, fd: int, size: int) -> None:
        self.fd = fd
        self.size = size
        self.buf = mmap.mmap(-1, max(1, size))
        self.filled = 0

    def fill_to(self, end: int) -> None:
        end = min(end, self.size)
        view = memoryview(self.buf)
        try:
            while self.filled < end:
                if hasattr(os, "preadv"):  # straight into place: no bytes object between
                    n = os.preadv(self.fd, [view[self.filled:end]], self.filled)
                else:
                    chunk = os.pread(self.fd, min(end - self.filled, 8 << 20), self.filled)
                    n = len(chunk)
                    view[self.filled:self.filled + n] = chunk
                if n <= 0:
                    raise OSError(f"the file ends at byte {self.filled}, its pages reach byte {end}")
                self.filled += n
        finally:
            view.release()

    def release(self, start: int, end: int) -> None:
        """Give back the whole memory pages inside ``start..end`` (a page's strips, never its IFD)."""
        lo = -(-start // mmap.PAGESIZE) * mmap.PAGESIZE
        hi = min(end, self.filled) // mmap.PAGESIZE * mmap.PAGESIZE
        if hi > lo and hasattr(mmap, "MADV_DONTNEED"):
            self.buf.madvise(mmap.MADV_DONTNEED, lo, hi - lo)

    def close(self) -> None:
        self.buf.close()


def _page_end(page: Any) -> int:
    """Where the last byte libtiff reads for ``page`` ends: its IFD, its tags' values, its strips."""
    fmt = page.parent.tiff  # classic TIFF or BigTIFF: the sizes of an IFD's parts
    ends = [int(page.offset) + fmt.tagnosize + fmt.tagsize * len(page.tags) + fmt.offsetsize]
    ends += [int(t.valueoffset) + int(t.valuebytecount) for t in page.tags.values()
             if t.valuebytecount > fmt.tagoffsetthreshold]
    return max(*ends, _strip_span(page)[1])


def _strip_span(page: Any) -> tuple[int, int]:
    """(first, end) byte of the page's strips; (0, 0) for a page without any."""
    return (int(min(page.dataoffsets, default=0)),
            int(max((o + n for o, n in zip(page.dataoffsets, page.databytecounts, strict=True)), default=0)))


def _libtiff_pages(image: _FileImage, tif: tifffile.TiffFile, workers: int = 2) -> Iterator[DecodedFrame]:
    """The pages of one open file, pixels decoded by libtiff (imagecodecs' ``tiff_decode``) from
    the file's bytes as reads bring them (``_FileImage``).

    Why libtiff: it is the reference TIFF reader, independent of the LZW encoder that wrote the
    strips, and its LZW decoder is faster than the one tifffile calls: verifying a 640x512 page
    took 3.7 CPU ms against 4.2, sha256 included. It releases the GIL, so ``workers`` calls decode
    at once: on two cores, alone, verifying a copy takes half the wall time (1.9 against 4.2 ms a
    page).
    Verification reads every page of a copy this way. A page whose kind libtiff's batch call
    cannot stack (another shape or type) is decoded alone."""
    pages = iter(tif.pages)

    def batches() -> Iterator[tuple[int, list[tuple[Any, tuple[bytes, int | None]]]]]:
        # tags are read here, on the one thread that moves tifffile's file position
        first = next(pages, None)
        if first is None:
            return
        per_call = max(1, min(PAGES_PER_CALL, BYTES_PER_CALL // max(1, int(first.nbytes))))
        rest, start = itertools.chain([first], pages), 0
        while True:
            batch = [(p, _page_tags(p)) for _, p in zip(range(per_call), rest, strict=False)]
            if not batch:
                return
            image.fill_to(max(_page_end(p) for p, _ in batch))  # a read that fails raises here
            yield start, batch
            start += len(batch)

    def decode(item: tuple[int, list[tuple[Any, tuple[bytes, int | None]]]]) \
            -> tuple[list[tuple[int, int]], list[DecodedFrame]]:
        start, batch = item
        first = batch[0][0]
        stack: Any = None
        if len({(p.shape, p.dtype) for p, _ in batch}) == 1:
            stack = imagecodecs.tiff_decode(image.buf, index=slice(start, start + len(batch)))
            stack = stack.reshape((len(batch), *first.shape)) if stack.size == len(batch) * first.size else None
        if stack is None:
            stack = [imagecodecs.tiff_decode(image.buf, index=start + k) for k in range(len(batch))]
        out = []
        for k, (page, tags) in enumerate(batch):
            pixels = np.asarray(stack[k])
            if pixels.shape != page.shape or pixels.dtype != page.dtype:
                raise ValueError(f"page {start + k}: libtiff decoded {pixels.dtype} {pixels.shape}, "
                                 f"its tags say {page.dtype} {page.shape}")
            out.append(DecodedFrame(pixels, *tags))
        return [_strip_span(p) for p, _ in batch], out

    for spans, decoded in ordered_map(decode, batches(), workers, window=3):
        yield from decoded
        for lo, hi in spans:  # decoded into arrays of their own: the strips' memory goes back
            image.release(lo, hi)


def _page_tags(page: Any) -> tuple[bytes, int | None]:
    """(sidecar, log time) of a page: ImageDescription, and the time tag or the sidecar's time."""
    desc = page.tags.get(270)
    sidecar = desc.value.encode("utf-8") if desc is not None else b""
    stamp = page.tags.get(LOG_TIME_TAG)
    return sidecar, int(stamp.value) if stamp is not None else time_from_sidecar(sidecar)


def _decoded(page: Any) -> DecodedFrame:
    return DecodedFrame(page.asarray(), *_page_tags(page))
