"""Errors of the recorder package.

ThermcapError                 root of every error thermcap raises on purpose
 +-- SidecarError             a sidecar does not follow the ICD schema (names the field)
 +-- SourceError              a frame source cannot deliver (names the file and the problem)
 |    +-- TruncatedFrameError a raw stream ended inside a frame (names the byte count)
 |    +-- ImportFileError     a file cannot be imported: corrupt, unsupported, unreadable (names it)
 |         +-- TruncatedImageError a SEQ/CSQ ends inside an image (the images before it are kept)
 +-- RecordingError           the writer had to stop (disk full, unwritable folder)
 +-- McapFileError            an MCAP file is unreadable or truncated (names the file)
 +-- SessionBusyError         another process holds the session's lock (names it)
 +-- StorageError             a file or folder cannot be written (read-only, full, permissions; names it)
"""

from __future__ import annotations


class ThermcapError(Exception):
    """Root of the errors thermcap raises on purpose; the CLI turns them into a message and exit 1."""


class SidecarError(ThermcapError, ValueError):
    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"sidecar field {field!r}: {problem}")


class SourceError(ThermcapError):
    pass


class TruncatedFrameError(SourceError):
    def __init__(self, path: str, frame_index: int, got: int, expected: int):
        self.path, self.frame_index, self.got, self.expected = path, frame_index, got, expected
        super().__init__(
            f"{path}: frame {frame_index} is truncated: got {got} bytes, expected {expected} "
            f"({frame_index} complete frames before it were kept)"
        )


class ImportFileError(SourceError):
    """A file could not be imported; the message names the file and the problem."""


class TruncatedImageError(ImportFileError):
    """A multi-image file (SEQ, CSQ) ends inside an image: the images before it are complete and
    are imported; this one is reported by its byte count, as the raw source reports a cut frame."""

    def __init__(self, path: str, image: int, at_byte: int, got: int, expected: int) -> None:
        self.path, self.image, self.at_byte, self.got, self.expected = path, image, at_byte, got, expected
        super().__init__(f"{path}: image {image} at byte {at_byte} is cut: {got} of its {expected} bytes are there "
                         f"({image} complete images before it were imported)")


class RecordingError(ThermcapError):
    pass


class McapFileError(ThermcapError):
    pass


class SessionBusyError(ThermcapError):
    """Another process (a recorder, an archiver, recover, gc) holds the session's lock."""


class StorageError(ThermcapError):
    """A file or folder cannot be read or written (read-only disk, no space, permissions)."""
