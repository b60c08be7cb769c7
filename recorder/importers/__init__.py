"""Importers: real thermal files into frames with their radiometric models, by content.

``read_file(path)`` detects the format from the bytes (never the extension alone), and returns
the frames or raises ImportFileError naming the file and the problem. Formats: FLIR radiometric
JPEG / FFF / SEQ / CSQ, DJI R-JPEG (iirp, dirp, girp, hirp), TERRA-REF ``_ir.bin``, ICD TIFF
and raw Gray16 with their JSON sidecars, ROS 2 bags (MCAP or sqlite3 storage) of a 16-bit image topic.
"""

from __future__ import annotations

from collections.abc import Generator
from pathlib import Path

from thermcap.recorder.importers.base import ImportedFrame, ImportFileError, TruncatedImageError
from thermcap.recorder.importers.dji import is_dji, read_dji
from thermcap.recorder.importers.file_view import FileView
from thermcap.recorder.importers.flir import iter_fff_file, read_fff_file, read_flir_jpeg
from thermcap.recorder.importers.icd_files import iter_icd_tiff, read_icd_raw, read_icd_tiff, sidecar_for
from thermcap.recorder.importers.jpeg import app_segments
from thermcap.recorder.importers.ros2_bag import (
    MCAP_MAGIC,
    SQLITE_MAGIC,
    is_ros2_bag,
    is_ros2_db3,
    iter_ros2_bag,
    iter_ros2_db3,
)
from thermcap.recorder.importers.terraref import metadata_for, read_terraref

__all__ = ["MAX_FILE_BYTES", "ImportFileError", "ImportedFrame", "TruncatedImageError", "detect", "iter_file",
           "read_file"]

MAX_FILE_BYTES = 4 * 1024**3
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # classic and BigTIFF, either byte order


def detect(path: str, data: bytes) -> str:
    if data[:2] == b"\xff\xd8":
        segments = app_segments(path, data)
        if any(m == 0xE1 and p[:5] == b"FLIR\x00" for m, p in segments):
            return "flir-rjpeg"
        if is_dji(segments):
            return "dji-rjpeg"
        raise ImportFileError(f"{path}: a JPEG with no thermal data (neither FLIR nor DJI radiometric)")
    if data[:4] in (b"FFF\x00", b"AFF\x00"):
        return "flir-fff"
    if data[:4] in _TIFF_MAGIC:
        return "tiff"
    if metadata_for(path) is not None:
        return "terraref-bin"
    if sidecar_for(path) is not None and Path(path).suffix.lower() in (".raw", ".gray16", ".bin"):
        return "icd-raw"
    if data[:8] == MCAP_MAGIC:
        if is_ros2_bag(path):
            return "ros2-bag"
        raise ImportFileError(f"{path}: an MCAP file with no ROS 2 image topic (sensor_msgs/msg/Image); "
                              "a thermcap session's segments are a session already (`thermcap info` them)")
    if data[:16] == SQLITE_MAGIC and is_ros2_db3(path):
        return "ros2-db3"
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        raise ImportFileError(f"{path}: a PNG image; thermcap imports radiometric files (FLIR, DJI, TERRA-REF, ICD)")
    raise ImportFileError(f"{path}: unrecognised file (not a FLIR/DJI radiometric JPEG, FFF/SEQ/CSQ, TIFF, "
                       "TERRA-REF _ir.bin, ICD raw with a .json sidecar or a ROS 2 bag, MCAP or .db3)")


def read_file(path: str | Path, *, terraref_variant: str = "pipeline") -> list[ImportedFrame]:
    """``terraref_variant``: which TERRA-REF Planck form uncalibrated gantry files get (see
    :class:`~recorder.radiometry.TerraRefPlanckModel`)."""
    path = str(path)
    data = _file_bytes(path)
    kind = detect(path, data)
    try:
        if kind == "flir-rjpeg":
            return read_flir_jpeg(path, data)
        if kind == "dji-rjpeg":
            return read_dji(path, data)
        if kind == "flir-fff":
            return read_fff_file(path, data)
        if kind == "tiff":
            return read_icd_tiff(path, data)
        if kind == "terraref-bin":
            return read_terraref(path, data, variant=terraref_variant)
        if kind == "ros2-bag":
            return list(iter_ros2_bag(path))
        if kind == "ros2-db3":
            return list(iter_ros2_db3(path))
        return read_icd_raw(path, data)
    except ImportFileError:
        raise
    except Exception as exc:  # a corrupt file may trip any parser: still a clean, named error
        raise ImportFileError(f"{path}: corrupt {kind} file ({type(exc).__name__}: {exc})") from None


def _file_bytes(path: str) -> bytes:
    """The whole file, for the formats parsed from memory (up to ``MAX_FILE_BYTES``)."""
    try:
        size = Path(path).stat().st_size
        if size > MAX_FILE_BYTES:
            raise ImportFileError(f"{path}: {size} bytes is larger than the {MAX_FILE_BYTES} an importer reads")
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ImportFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not data:
        raise ImportFileError(f"{path}: empty file")
    return data


def iter_file(path: str | Path, *, terraref_variant: str = "pipeline") -> Generator[ImportedFrame, None, None]:
    """Like ``read_file``, one frame at a time. FFF/SEQ/CSQ files are read and decoded image by
    image (``FileView``), so an hours-long SEQ costs one frame of memory, not the file; a TIFF
    stack is decoded page by page (from its bytes, read whole); the other formats hold one frame
    a file anyway. A corrupt image mid-file raises ImportFileError there
    (the frames before it were already yielded: callers that must not half-import keep track)."""
    path = str(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
            if head == MCAP_MAGIC[:4] and fh.read(4) == MCAP_MAGIC[4:] and is_ros2_bag(path):
                fh.close()
                yield from iter_ros2_bag(path)  # a message at a time, however long the bag
                return
            if head == SQLITE_MAGIC[:4] and is_ros2_db3(path):
                fh.close()
                yield from iter_ros2_db3(path)
                return
            if head in _TIFF_MAGIC:  # a stack of pages: decoded one page at a time
                fh.close()
                yield from iter_icd_tiff(path, _file_bytes(path))
                return
            if head not in (b"FFF\x00", b"AFF\x00"):
                fh.close()
                yield from read_file(path, terraref_variant=terraref_variant)
                return
            try:  # read by offset, never mapped: see FileView
                yield from iter_fff_file(path, FileView(path, fh.fileno()))
            except ImportFileError:
                raise
            except Exception as exc:  # a corrupt file may trip any parser: still a clean, named error
                raise ImportFileError(f"{path}: corrupt flir-fff file ({type(exc).__name__}: {exc})") from None
    except OSError as exc:
        raise ImportFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
