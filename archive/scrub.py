"""``thermcap scrub``: re-verify every archived copy, mark the damaged ones, repair them.

Disks rot and copies get damaged after they verified. Scrub re-reads each session's archive
formats (every frame decoded by the format's reader, pixels, sidecar and time against the
manifest), ``extras.mcap`` (its hash and content digests), and the object-store copies (each
object re-read and hashed). A damaged copy is marked in the manifest (``damaged``), so the API's
index stops offering it and gc no longer counts it as cover.

With ``repair``, every format is rebuilt from another verified copy (all formats are lossless,
so any one regenerates another; the MCAP source is used when it is still there), verified like
a new archive, and only then put in place of the damaged one. A damaged ``extras.mcap`` is
rebuilt from the source or taken back from a verified bucket copy; a damaged bucket object is
uploaded again from a verified local copy. Each repaired copy is verified again.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from thermcap.archive.archiver import build_format
from thermcap.archive.blobs import BlobStore, stored_digest
from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.extras import write_extras
from thermcap.archive.formats import get_format
from thermcap.archive.manifest import (
    DEFAULT_DIGEST,
    archived_files,
    digest_problem,
    iso_now,
    load_manifest,
    record_digest,
    save_manifest,
)
from thermcap.archive.manifest_types import ExtrasEntry, FormatEntry, FramesBlock, Manifest
from thermcap.archive.reading import frames_from_format, verified_formats
from thermcap.archive.verify import verify_extras, verify_format
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import iter_session_frames, list_sessions, read_session_meta, session_segments

__all__ = ["ScrubFinding", "ScrubReport", "scrub_root", "scrub_session"]


@dataclass
class ScrubFinding:
    session: str
    copy: str  # "png16", "extras", "store:<key>"
    problems: list[str]
    repaired: bool = False
    repaired_from: str | None = None
    repair_error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class ScrubReport:
    sessions: int = 0
    copies_checked: int = 0
    skipped: dict[str, str] = field(default_factory=dict)  # session -> who holds it
    findings: list[ScrubFinding] = field(default_factory=list)

    @property
    def damaged(self) -> int:
        return len(self.findings)

    @property
    def repaired(self) -> int:
        return sum(1 for f in self.findings if f.repaired)

    @property
    def ok(self) -> bool:
        return all(f.repaired for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        return {"sessions": self.sessions, "copies_checked": self.copies_checked, "damaged": self.damaged,
                "repaired": self.repaired, "ok": self.ok, "skipped": self.skipped,
                "findings": [f.to_dict() for f in self.findings]}


def scrub_root(root: Path, *, repair: bool = False, store: BlobStore | None = None, workers: int = 2) -> ScrubReport:
    report = ScrubReport()
    for d in list_sessions(root):
        if SessionLayout.of(d).manifest.is_file():
            scrub_session(d, repair=repair, store=store, root=root, workers=workers, report=report)
    return report


def scrub_session(session_dir: Path, *, repair: bool = False, store: BlobStore | None = None,
                  root: Path | None = None, workers: int = 2, report: ScrubReport | None = None) -> ScrubReport:
    report = report if report is not None else ScrubReport()
    lock = lock_session(session_dir, "scrub", wait_s=0.0)
    if lock is None:
        report.skipped[str(session_dir)] = holder(session_dir) or "another process"
        return report
    try:
        report.sessions += 1
        _scrub_locked(Path(session_dir), repair, store, Path(root) if root else Path(session_dir).parents[1],
                      workers, report)
    finally:
        lock.release()
    return report


def _scrub_locked(d: Path, repair: bool, store: BlobStore | None, root: Path, workers: int,
                  report: ScrubReport) -> None:
    layout = SessionLayout.of(d)
    m = load_manifest(d)
    frames = m.get("frames", {})
    findings: list[ScrubFinding] = []
    for fid, entry in sorted(m.get("formats", {}).items()):
        if not entry.get("verified"):
            continue
        report.copies_checked += 1
        problems = _format_problems(layout, fid, entry, frames)
        _mark(entry, problems)
        if problems:
            findings.append(ScrubFinding(str(d), fid, problems[:20]))
    extras = m.get("extras") or {}
    if extras.get("verified"):
        report.copies_checked += 1
        problems = verify_extras(layout.archive, extras).problems
        _mark(extras, problems)
        if problems:
            findings.append(ScrubFinding(str(d), "extras", problems[:20]))
    if store is not None and (m.get("upload") or {}).get("complete"):
        damaged_keys = {}
        for key, sha in _uploaded_hashes(m, d, root).items():
            report.copies_checked += 1
            problem = _check_object(store, key, sha)
            if problem:
                damaged_keys[key] = problem
                findings.append(ScrubFinding(str(d), f"store:{key}", [problem]))
        m["upload"]["damaged"] = damaged_keys
    m["scrubbed_at"] = iso_now()
    save_manifest(d, m)
    if repair:
        for finding in findings:
            _repair(d, layout, m, finding, store, root, workers)
        save_manifest(d, m)
    report.findings += findings


def _format_problems(layout: SessionLayout, fid: str, entry: FormatEntry, frames: FramesBlock) -> list[str]:
    try:
        return verify_format(layout.dir, fid, entry, frames)
    except ArchiveError as exc:  # a format id this version cannot read is reported, not fatal
        return [str(exc)]


def _mark(entry: FormatEntry | ExtrasEntry, problems: list[str]) -> None:
    if problems:
        entry["damaged"] = {"at": iso_now(), "problems": problems[:20]}
    else:
        entry.pop("damaged", None)


def _uploaded_hashes(m: Manifest, d: Path, root: Path) -> dict[str, tuple[str, str]]:
    """Object key -> (hash, digest) the manifest recorded for that file."""
    rel = d.resolve().relative_to(root.resolve()).as_posix()
    out = {f"{rel}/archive/{f.rel}": f.named for f in archived_files(m)}
    uploaded = set((m.get("upload") or {}).get("keys", []))
    return {k: v for k, v in out.items() if k in uploaded}


def _check_object(store: BlobStore, key: str, named: tuple[str, str] | None) -> str | None:
    if named is None:
        return "the manifest names no digest for it"
    try:
        got = stored_digest(store, key, named[0])
    except Exception as exc:  # a network or store error is reported, not taken for damage-free
        return f"cannot be read ({type(exc).__name__}: {exc})"
    if got is None:
        return "missing from the store"
    return None if got == named[1] else f"{named[0]} differs from the manifest"


def _repair(d: Path, layout: SessionLayout, m: Manifest, finding: ScrubFinding, store: BlobStore | None,
            root: Path, workers: int) -> None:
    try:
        if finding.copy == "extras":
            _repair_extras(d, layout, m, finding, store, root)
        elif finding.copy.startswith("store:"):
            _repair_object(d, layout, m, finding, store, root)
        else:
            _repair_format(d, layout, m, finding, workers)
    except Exception as exc:  # a repair that fails leaves the damage marked and says why
        finding.repair_error = f"{type(exc).__name__}: {exc}"


def _repair_format(d: Path, layout: SessionLayout, m: Manifest, finding: ScrubFinding, workers: int) -> None:
    fid = finding.copy
    if session_segments(d):
        source, frames = "mcap source", iter_session_frames(d)
    else:
        good = verified_formats(m, layout, but=fid)
        if not good:
            finding.repair_error = "no other verified copy to rebuild it from"
            return
        source, frames = good[0], frames_from_format(m, layout, good[0])
    entry = m["formats"][fid]
    per_segment: dict[str, int] = {s["name"]: s["frames"] for s in m.get("source", {}).get("segments", [])}
    problems = build_format(d, fid, get_format(entry.get("config") or fid), frames, m, read_session_meta(d),
                            per_segment, workers=workers)
    if problems:
        finding.repair_error = "; ".join(problems[:5])
        return
    again = _format_problems(layout, fid, m["formats"][fid], m["frames"])  # verified again, as the issue asks
    _mark(m["formats"][fid], again)
    finding.repaired, finding.repaired_from = not again, source


def _repair_extras(d: Path, layout: SessionLayout, m: Manifest, finding: ScrubFinding, store: BlobStore | None,
                   root: Path) -> None:
    extras = m["extras"]
    if session_segments(d):
        named = record_digest(extras)
        entry = write_extras(d, layout.archive, named[0] if named else DEFAULT_DIGEST)
        if entry.get("verified") and record_digest(entry) == record_digest(extras):
            m["extras"] = entry
            finding.repaired, finding.repaired_from = True, "mcap source"
            return
    key = f"{d.resolve().relative_to(root.resolve()).as_posix()}/archive/{extras['path']}"
    if store is not None and store.kind == "s3" and _check_object(store, key, record_digest(extras)) is None:
        with tempfile.NamedTemporaryFile(dir=layout.archive, delete=False, suffix=".partial") as tmp:
            for piece in store.iter_bytes(key):
                tmp.write(piece)
            tmp.flush()
            os.fsync(tmp.fileno())
        os.replace(tmp.name, layout.extras)
        problems = verify_extras(layout.archive, extras).problems
        _mark(extras, problems)
        finding.repaired, finding.repaired_from = not problems, "store"
        return
    finding.repair_error = "no MCAP source and no verified bucket copy to rebuild extras.mcap from"


def _repair_object(d: Path, layout: SessionLayout, m: Manifest, finding: ScrubFinding,
                   store: BlobStore | None, root: Path) -> None:
    assert store is not None
    key = finding.copy[len("store:"):]
    rel = key.split("/archive/", 1)[1]
    local = layout.archive / rel
    want = _uploaded_hashes(m, d, root)[key]
    if digest_problem(local, want) is not None:
        finding.repair_error = f"no verified local copy of {rel} to upload again"
        return
    store.put_file(key, local, overwrite=True)  # the object is known bad: replacing it is the repair
    problem = _check_object(store, key, want)
    if problem is None:
        m["upload"].get("damaged", {}).pop(key, None)
    finding.repaired, finding.repaired_from = problem is None, "local copy"
