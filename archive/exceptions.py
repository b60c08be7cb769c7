"""Errors of the archive package.

ArchiveError (a ThermcapError)   root: the CLI prints it and exits 1
 +-- UnknownCodecError           no codec or format registered under that id
 +-- VerificationError           an archive does not match its source or manifest (names frames and files)
 |    +-- SourceDamagedError      the MCAP source disagrees with itself; refused before anything is written
 +-- ManifestError               the manifest is missing or unreadable
LookupError
 +-- FrameNotFound               no such frame (or attachment), or a copy that is not there
 +-- FrameUnavailable            every copy of a frame is missing or damaged (each checked)
"""

from __future__ import annotations

from thermcap.recorder.exceptions import ThermcapError


class ArchiveError(ThermcapError):
    pass


class UnknownCodecError(ArchiveError, KeyError):
    def __init__(self, codec_id: str, known: list[str]):
        self.codec_id = codec_id
        super().__init__(f"unknown codec or format {codec_id!r}; known: {', '.join(sorted(known))}")

    def __str__(self) -> str:  # KeyError would quote the message
        return self.args[0]


class VerificationError(ArchiveError):
    def __init__(self, message: str, problems: list[str] | None = None):
        self.problems = problems or []
        more = f"\n  ... and {len(self.problems) - 50} more" if len(self.problems) > 50 else ""
        super().__init__(message + "".join(f"\n  {p}" for p in self.problems[:50]) + more)


class ManifestError(ArchiveError):
    pass


class SourceDamagedError(VerificationError):
    """The source's summary, channels or sidecars disagree with its data: nothing is archived."""


class FrameNotFound(LookupError):
    """The session has no such frame (or the frame no such attachment), or one copy of it is
    not there: a reader passes over a missing copy without calling it damaged."""


class FrameUnavailable(LookupError):
    """Every copy of a frame is missing or damaged (each was checked against the manifest)."""
