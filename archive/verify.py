"""``thermcap verify``: re-check archives against the manifest's hashes alone (the MCAP may be gone)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.archive.archiver import verify_format_dir
from thermcap.archive.formats import get_format
from thermcap.archive.manifest import archive_dir, file_problem, frame_proof, load_manifest
from thermcap.archive.manifest_types import ExtrasEntry, FormatEntry, FramesBlock

__all__ = ["CopyCheck", "verify_extras", "verify_format", "verify_session"]


@dataclass(frozen=True)
class CopyCheck:
    """One archived copy (a format, or extras) checked against the manifest."""

    frames: int
    problems: list[str] = field(default_factory=list)  # each names the frame or file and what differs

    @property
    def ok(self) -> bool:
        return not self.problems

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, **asdict(self)}


def verify_session(session_dir: str | Path, formats: list[str] | None = None) -> dict[str, CopyCheck]:
    """Each requested copy by id ("extras" for extras.mcap); a copy never verified or not in the
    manifest is a problem, not a skip, so a script cannot read silence as success."""
    session_dir = Path(session_dir)
    manifest = load_manifest(session_dir)
    expected = frame_proof(manifest["frames"]).pixels
    adir = archive_dir(session_dir)
    report: dict[str, CopyCheck] = {}
    for fid, entry in manifest["formats"].items():
        if formats and fid not in formats:
            continue
        if not entry.get("verified"):
            report[fid] = CopyCheck(0, [f"{fid}: never verified when archived"])
            continue
        problems = verify_format(session_dir, fid, entry, manifest["frames"])
        report[fid] = CopyCheck(len(expected), problems)
    extras = manifest.get("extras")
    if extras and not formats:
        report["extras"] = verify_extras(adir, extras)
    for fid in formats or []:
        if fid not in report:
            report[fid] = CopyCheck(0, [f"{fid}: not in the manifest"])
    return report


def verify_format(session_dir: Path, fid: str, entry: FormatEntry, frames: FramesBlock) -> list[str]:
    """Every frame of one archived format decoded by its reader and compared with the manifest's
    pixel and sidecar hashes and times; the problems, or [] (thermcap verify and scrub)."""
    fmt = get_format(entry.get("config") or fid)
    problems, _ = verify_format_dir(fmt, archive_dir(session_dir) / fid, entry.get("files", []),
                                    frame_proof(frames), where=fid, times=frames.get("timestamps_ns"))
    return problems


def verify_extras(adir: Path, entry: ExtrasEntry) -> CopyCheck:
    """extras.mcap: its digest, and every topic digest and attachment hash the manifest recorded."""
    from thermcap.archive.extras import summarize_mcap

    path = adir / entry["path"]
    if not entry.get("verified"):
        return CopyCheck(0, ["extras: never verified when archived"])
    if not path.is_file():
        return CopyCheck(0, [f"extras: {path} is missing"])
    problems = []
    problem = file_problem(path, entry)
    if problem is not None:
        problems.append(f"extras: {path} {problem}")
    else:
        got = summarize_mcap([path])
        if got["topics"] != entry["topics"] or got["attachments"] != entry["attachments"]:
            problems.append(f"extras: {path} content differs from what the manifest recorded")
    return CopyCheck(0, problems)
