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

__all__ = ["Cover", "copy_problems", "extras_problems", "local_cover"]


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
    return Cover(relies, problems)
