"""``thermcap verify``: re-check archives against the manifest's hashes alone (the MCAP may be gone)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from archive.archiver import verify_format_dir
from archive.formats import get_format
from archive.manifest import archive_dir, file_sha256, load_manifest
from archive.manifest_types import ExtrasEntry, FormatEntry, FramesBlock

__all__ = ["verify_extras", "verify_format", "verify_session"]


def verify_session(session_dir: str | Path, formats: list[str] | None = None) -> dict[str, Any]:
    """Returns {format: {"ok": bool, "problems": [...], "frames": n}}; names every bad frame and file."""
    session_dir = Path(session_dir)
    manifest = load_manifest(session_dir)
    expected = manifest["frames"].get("sha256", [])
    adir = archive_dir(session_dir)
    report: dict[str, Any] = {}
    for fid, entry in manifest["formats"].items():
        if formats and fid not in formats:
            continue
        if not entry.get("verified"):
            report[fid] = {"ok": False, "frames": 0, "problems": [f"{fid}: never verified when archived"]}
            continue
        problems = verify_format(session_dir, fid, entry, manifest["frames"])
        report[fid] = {"ok": not problems, "frames": len(expected), "problems": problems}
    extras = manifest.get("extras")
    if extras and not formats:
        report["extras"] = verify_extras(adir, extras)
    for fid in formats or []:
        if fid not in report:
            report[fid] = {"ok": False, "frames": 0, "problems": [f"{fid}: not in the manifest"]}
    return report


def verify_format(session_dir: Path, fid: str, entry: FormatEntry, frames: FramesBlock) -> list[str]:
    """Every frame of one archived format decoded by its reader and compared with the manifest's
    pixel and sidecar hashes and times; the problems, or [] (thermcap verify and scrub)."""
    fmt = get_format(entry.get("config") or fid)
    problems, _ = verify_format_dir(fmt, archive_dir(session_dir) / fid, entry.get("files", []),
                                    frames.get("sha256", []), where=fid, sidecars=frames.get("sidecar_sha256"),
                                    times=frames.get("timestamps_ns"))
    return problems


def verify_extras(adir: Path, entry: ExtrasEntry) -> dict[str, Any]:
    """extras.mcap: its sha256, and every topic digest and attachment hash the manifest recorded."""
    from archive.extras import summarize_mcap

    path = adir / entry["path"]
    if not entry.get("verified"):
        return {"ok": False, "frames": 0, "problems": ["extras: never verified when archived"]}
    if not path.is_file():
        return {"ok": False, "frames": 0, "problems": [f"extras: {path} is missing"]}
    problems = []
    if file_sha256(path) != entry["sha256"]:
        problems.append(f"extras: {path} sha256 differs from the manifest")
    else:
        got = summarize_mcap([path])
        if got["topics"] != entry["topics"] or got["attachments"] != entry["attachments"]:
            problems.append(f"extras: {path} content differs from what the manifest recorded")
    return {"ok": not problems, "frames": 0, "problems": problems}
