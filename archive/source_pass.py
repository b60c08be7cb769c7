"""The one read of an MCAP source that archiving needs.

Archiving used to decompress a session's segments again for every job: a hash scan, each
format's writer, and the extras. ``SourcePass.frames()`` reads them once. Each frame is hashed
(pixels, sidecar, time) and checked on its way to the formats' writers, and every other
message goes to the ``ExtrasWriter`` from the same decompressed chunk. Only when the stream
has ended, and the source agreed with itself, does the pass give the manifest its hashes:
a source that disagrees with itself (a frame without its sidecar, summaries that count other
frames than the data holds, a damaged channel record) raises ``SourceDamagedError`` at the
end of the stream. The formats' writers then fail too, and nothing takes a name.

A frame's pixels are a view into its decompressed chunk, at whatever byte the message put them:
about half of a recording's frames start at an odd address, where uint16 is not aligned. Every
codec then reads them by its unaligned path (numpy's, for one), three codecs a frame. The pass
gives those frames a copy in aligned memory as it reads them (read-only, like the view), which its
own hashes and summary then read as well: one copy of 655 KB costs
less than what it saves, 16.16 -> 15.93 and 16.53 -> 16.39 ms a 640x512 frame for the whole
archive with the default formats (medians of 5, alternated in one process, 2026-12-06).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from thermcap.archive.exceptions import SourceDamagedError
from thermcap.archive.extras import ExtrasWriter
from thermcap.archive.frame_summary import SummaryBuilder
from thermcap.archive.manifest import DEFAULT_DIGEST, FrameProof
from thermcap.archive.read_back import frame_xxh3
from thermcap.archive.source_checks import channel_problems
from thermcap.recorder.icd.topics import TOPIC_METADATA
from thermcap.recorder.storage.reader import SessionFrame, iter_segment_frames, session_segments

__all__ = ["SourceHashes", "SourcePass"]


@dataclass
class SourceHashes:
    """What verification compares every copy with: one entry per frame, in session order."""

    proof: FrameProof = field(default_factory=lambda: FrameProof(DEFAULT_DIGEST, [], []))
    timestamps_ns: list[int] = field(default_factory=list)
    segments: list[str] = field(default_factory=list)
    #: xxh3-128 of the same pixels, for this run's read-back alone (``read_back``); not kept
    xxh3: list[bytes] = field(default_factory=list)
    width: int = 0
    height: int = 0


class SourcePass:
    """``frames()`` once; then ``hashes`` (None when ``hash_frames`` is off: the manifest already
    has them, and they stay what copies are compared with), the extras, if given a writer, and
    the frame summary, if given a builder."""

    def __init__(self, session_dir: Path, per_segment: dict[str, int], *, hash_frames: bool = True,
                 extras: ExtrasWriter | None = None, summary: SummaryBuilder | None = None,
                 segments: list[Path] | None = None, first_index: int = 0, digest: str = DEFAULT_DIGEST) -> None:
        self.session_dir = session_dir
        self.segments = segments  # a part of the session (one segment's task); None: all of it
        self.first_index = first_index
        self.per_segment = per_segment
        self.hash_frames = hash_frames
        self.extras = extras
        self.summary = summary
        self.hashes: SourceHashes | None = None
        self.digest = digest

    def frames(self) -> Iterator[SessionFrame]:
        segments = self.segments if self.segments is not None else session_segments(self.session_dir)
        problems = [f"{seg.name}: {p}" for seg in segments for p in channel_problems(seg)]
        if problems:  # before anything is written
            self._refuse(problems)
        got = SourceHashes(FrameProof(self.digest, [], []))
        proof = got.proof
        read: dict[str, int] = {}
        others = self.extras.add_message if self.extras is not None else None
        index = self.first_index
        for seg in segments:
            for f in iter_segment_frames(seg, first_index=index, others=others):
                if not f.pixels.flags.aligned:  # before the hashes and the summary read it too
                    f = replace(f, pixels=_aligned(f.pixels))
                if self.hash_frames:
                    proof.pixels.append(proof.of_pixels(f.pixels))
                    got.xxh3.append(frame_xxh3(f.pixels))
                    proof.sidecars.append(proof.of_sidecar(f.sidecar))
                    got.timestamps_ns.append(f.log_time)
                    got.segments.append(f.segment)
                if got.width and f.pixels.shape != (got.height, got.width):
                    raise SourceDamagedError(
                        f"{self.session_dir}: frame {f.index} ({f.segment}) is {f.pixels.shape[1]}x"
                        f"{f.pixels.shape[0]}, the session's first frame {got.width}x{got.height}; a session's "
                        f"frames are of one size (one sensor), so nothing was archived",
                        [f"{f.segment}: frame {f.index} is {f.pixels.shape[1]}x{f.pixels.shape[0]}"])
                if self.summary is not None:
                    self.summary.add(f.pixels)
                read[f.segment] = read.get(f.segment, 0) + 1
                if not f.sidecar and len(problems) < 20:
                    problems.append(f"{f.segment}: frame {f.index} has no sidecar on {TOPIC_METADATA}")
                got.height, got.width = f.pixels.shape
                index = f.index + 1
                yield f
        for name, n in self.per_segment.items():
            if read.get(name, 0) != n:
                problems.append(f"{name}: its summary counts {n} frames, its data holds {read.get(name, 0)}")
        if problems:
            self._refuse(problems)
        if self.hash_frames:
            self.hashes = got

    def _refuse(self, problems: list[str]) -> None:
        raise SourceDamagedError(f"{self.session_dir}: the MCAP source disagrees with itself; nothing was archived "
                                 f"(`thermcap info` names the segments; `thermcap recover SEGMENT` repairs one in "
                                 f"place, keeping every intact chunk, and `--keep-original` keeps the damaged file "
                                 f"beside it)", problems)


def _aligned(pixels: np.ndarray) -> np.ndarray:
    """A read-only copy in aligned memory: the consumers share it, as they shared the view."""
    out = np.array(pixels)
    out.flags.writeable = False
    return out
