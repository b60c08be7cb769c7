"""What a destructive step may rely on, checked at the moment it acts.

The manifest's ``verified: true`` records that a copy once decoded bit-exact; disks rot, files
get removed and ``scrub`` marks copies ``damaged`` after that. So nothing that deletes, skips or
replaces data takes the flag at its word: it asks here, and here the files are hashed again
against the manifest (the hashes that were recorded when the copy decoded bit-exact), and a copy
marked damaged counts as not verified whatever its files say now. ``archive`` (skipping a format
as done, ``--delete-source``) and ``gc`` share these checks.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from thermcap.archive.manifest import file_problem
from thermcap.archive.manifest_types import ExtrasEntry, FormatEntry, Manifest
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.ledger import lost_segments

__all__ = ["Cover", "copy_problems", "extras_problems", "local_cover", "source_problems"]


def copy_problems(layout: SessionLayout, fid: str, entry: FormatEntry | None) -> list[str]:
    """Why format ``fid``'s copy cannot be counted as verified now; [] when it can. Every file
    is read and hashed: the check costs one read of the copy."""
    if not entry or not entry.get("verified"):
        return [f"{fid}: not verified"]
    if entry.get("damaged"):
        first = (entry["damaged"].get("problems") or ["damaged"])[0]
        return [f"{fid}: marked damaged by scrub ({first})"]
    files = entry.get("files") or []
    if not files:
        return [f"{fid}: the manifest lists no files"]
    problems = []
    for rec in files:
        problem = file_problem(layout.format_dir(fid) / rec["path"], rec)
        if problem is not None:
            problems.append(f"{fid}/{rec['path']}: {problem}")
    return problems


def extras_problems(layout: SessionLayout, entry: ExtrasEntry | None) -> list[str]:
    """Why ``extras.mcap`` (attachments, metadata, other topics) cannot be counted as verified now."""
    if not entry or not entry.get("verified"):
        return ["extras.mcap: not verified"]
    if entry.get("damaged"):
        return ["extras.mcap: marked damaged by scrub"]
    problem = file_problem(layout.extras, entry)
    return [] if problem is None else [f"extras.mcap: {problem}"]


@dataclass(frozen=True)
class Cover:
    """Whether the local archive covers the MCAP source: what deleting the source relies on, or
    the problems that forbid it."""

    relies_on: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def local_cover(layout: SessionLayout, manifest: Manifest, formats: Iterable[str]) -> Cover:
    """Every format of ``formats`` and ``extras.mcap`` re-checked against the manifest now."""
    relies: list[str] = []
    problems: list[str] = []
    for fid in formats:
        entry = manifest.get("formats", {}).get(fid)
        found = copy_problems(layout, fid, entry)
        if found:
            problems += found
        else:
            assert entry is not None
            relies.append(f"{fid}: {len(entry.get('files', []))} files verified {entry.get('verified_at')}, "
                          f"hashes rechecked")
    found = extras_problems(layout, manifest.get("extras"))
    problems += found
    if not found:
        relies.append("extras.mcap verified, hash rechecked")
    found = source_problems(layout, manifest)
    problems += found
    if not found:
        relies.append("every segment on disk is one the archive covers, and none the recorder wrote is missing")
    return Cover(relies, problems)


def source_problems(layout: SessionLayout, manifest: Manifest) -> list[str]:
    """Why the segments on disk now are not exactly the ones the archive was made from: a segment
    the archive never saw (restored from a depot, renamed back from ``.unreadable``) or one that
    changed size since, and segments the recorder wrote that are gone with no record of why
    (``recorder.storage.ledger``). Deleting the source on such an archive loses frames."""
    covered = {s.get("name"): s.get("bytes") for s in (manifest.get("source") or {}).get("segments") or []}
    problems = []
    for seg in layout.segments():
        if seg.name not in covered:
            problems.append(f"{seg.name}: a segment the archive does not cover (archive the session again)")
        elif covered[seg.name] is not None and seg.stat().st_size != covered[seg.name]:
            problems.append(f"{seg.name}: {seg.stat().st_size:,} bytes, not the {covered[seg.name]:,} archived")
    for lost in lost_segments(layout.dir):
        problems.append(f"{lost.name}: {lost.frames} frames the recorder wrote, gone with no record of why")
    return problems
