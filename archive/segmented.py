"""Archiving a session segment by segment, in parallel, then finalizing it once.

Why: one session is one stream, so a cluster of workers could archive only as many sessions at
once as there are sessions. A segment is the unit the recorder already closes, so segments are
the unit of work here:

- ``archive_segment`` (one task per segment, on any worker that sees the session folder) makes
  one read of its segment. It writes every format's files for that segment into
  ``archive/.parts/<segment>.partial/`` and decodes each back with the format's own reader,
  comparing it with the segment's frame hashes. The segment's extras and summary are made in
  the same read. Only when all of that holds does the folder take the name
  ``.parts/<segment>/``, with ``part.json`` saying what it holds. A rerun finds a finished part
  and does nothing; a lost worker's ``.partial`` is replaced.
- ``finalize_session`` (one task per session, after its segments) holds the session lock. It
  writes the manifest from the parts and gives each format its final folder. Files that are
  one per segment (png16, tiff-lzw, ...) are linked as they are: the same bytes the segment
  task verified, checked again by their digest. ``hdf5``'s one file per session is assembled by
  copying the segments' compressed chunks (``read_direct_chunk`` / ``write_direct_chunk``),
  never encoded again, and is then decoded in full by HDF5 and compared with every frame's hash.
  The extras and the summary are joined, and the parts are removed once the manifest holds
  all of it.

The archive it leaves is the one ``archive_session`` writes: the same files, manifest and checks.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from thermcap.archive.archiver import (
    DEFAULT_FORMATS,
    BuiltCopy,
    _summary_intact,
    format_entry,
    fresh_partial,
    take_name,
    usable_cores,
    verify_format_dir,
    write_verified,
)
from thermcap.archive.exceptions import ArchiveError, SourceDamagedError, VerificationError
from thermcap.archive.extras import EXTRAS_NAME, ExtrasWriter, extras_from
from thermcap.archive.fanout import fan_out
from thermcap.archive.formats import ArchiveContext, get_format
from thermcap.archive.frame_summary import SUMMARY_NAME, FrameSummary, SummaryBuilder, load_summary
from thermcap.archive.manifest import (
    DEFAULT_DIGEST,
    FrameProof,
    archive_dir,
    file_digest,
    file_problem,
    frame_proof,
    load_manifest,
    new_manifest,
    save_manifest,
)
from thermcap.archive.manifest_types import ExtrasEntry, FramesBlock, Manifest, SummaryEntry
from thermcap.archive.read_back import ReadBack
from thermcap.archive.source_pass import SourcePass
from thermcap.recorder.storage.atomic import fsync_dir
from thermcap.recorder.storage.layout import PARTIAL_SUFFIX, PARTS_DIR
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import SessionFrame, read_session_meta, segment_span, session_segments
from thermcap.recorder.storage.segments import ACTIVE_SUFFIX

__all__ = ["PARTS", "SegmentPart", "archive_segment", "finalize_session", "plan_segments"]

PARTS = PARTS_DIR  # the layout's name, kept under the name callers use
PART_JSON = "part.json"


@dataclass
class SegmentPart:
    """What one segment's task made and proved (``part.json``)."""

    segment: str
    segment_bytes: int
    first_index: int
    frames: FramesBlock
    width: int
    height: int
    formats: dict[str, dict[str, Any]] = field(default_factory=dict)  # fid -> {files, encode_s, decode_s}

    @property
    def count(self) -> int:
        return len(frame_proof(self.frames).pixels)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SegmentPart:
        return cls(**d)


def parts_dir(session_dir: Path) -> Path:
    return archive_dir(session_dir) / PARTS


def plan_segments(session_dir: Path) -> list[tuple[str, int]]:
    """(segment name, its first frame's session index), from the segments' summaries."""
    first, out = 0, []
    for seg in session_segments(session_dir):
        out.append((seg.name, first))
        first += segment_span(seg)[2]
    return out


def _done_part(session_dir: Path, segment: Path, formats: list[str]) -> SegmentPart | None:
    path = parts_dir(session_dir) / segment.name / PART_JSON
    try:
        part = SegmentPart.from_dict(json.loads(path.read_text()))
    except (OSError, ValueError, TypeError):
        return None
    if part.segment_bytes != segment.stat().st_size or not set(formats) <= set(part.formats):
        return None
    if frame_proof(part.frames).name != DEFAULT_DIGEST:  # made before an upgrade: parts join under one hash
        return None
    return part


def _archived(session_dir: Path, formats: list[str]) -> bool:
    """Whether the session's archive already holds every one of ``formats``, its extras and its
    summary (another submitter's tasks finished it)."""
    try:
        m = load_manifest(session_dir, required=False)
    except ArchiveError:
        return False
    adir = archive_dir(session_dir)
    return m is not None and all(m["formats"].get(f, {}).get("verified") and (adir / f).is_dir() for f in formats) \
        and bool((m.get("extras") or {}).get("verified")) and _summary_intact(adir, m)


def archive_segment(session_dir: str | Path, segment: str, first_index: int,
                    formats: list[str] | tuple[str, ...] = DEFAULT_FORMATS, *, workers: int = 1) -> SegmentPart | None:
    """One segment's share of the archive, written and verified (idempotent); None when the
    session's archive already holds all of it."""
    session_dir = Path(session_dir)
    seg = session_dir / segment
    if not seg.is_file():
        raise ArchiveError(f"{seg}: no such segment (an .active one is still being recorded)")
    formats = list(formats)
    done = _done_part(session_dir, seg, formats)
    if done is not None:
        return done
    if _archived(session_dir, formats):
        return None
    fmts = {fid: get_format(fid) for fid in formats}
    parts = parts_dir(session_dir)
    locks = parts / ".locks" / segment
    locks.mkdir(parents=True, exist_ok=True)
    # The same task elsewhere (another submitter's cluster, or a lost worker's process that has
    # not died yet): wait for it, then find its part. The lock dies with its holder.
    lock = lock_session(locks, f"segment task {segment}", wait_s=3600.0)
    if lock is None:
        raise ArchiveError(f"{seg}: {holder(locks) or 'another process'} has been archiving this segment for an hour")
    try:
        return _archive_segment_locked(session_dir, seg, first_index, formats, fmts, parts, workers)
    finally:
        lock.release()


def _archive_segment_locked(session_dir: Path, seg: Path, first_index: int, formats: list[str],
                            fmts: dict[str, Any], parts: Path, workers: int) -> SegmentPart | None:
    segment = seg.name
    done = _done_part(session_dir, seg, formats)  # made while we waited for the lock
    if done is not None:
        return done
    if _archived(session_dir, formats):
        return None
    partial = parts / (segment + PARTIAL_SUFFIX)
    if partial.exists():  # a lost worker's: never taken for a part
        shutil.rmtree(partial)
    partial.mkdir()
    meta = read_session_meta(session_dir)
    session_id = meta.get("session_id", session_dir.name)
    n = segment_span(seg)[2]
    summary = SummaryBuilder(n)
    source = SourcePass(session_dir, {segment: n}, extras=ExtrasWriter(partial), summary=summary, segments=[seg],
                        first_index=first_index)
    ctx = ArchiveContext(session_id=session_id, session_meta=meta, total_frames=n, frames_per_segment={segment: n},
                         workers=workers)

    def expected() -> ReadBack:
        h = source.hashes
        assert h is not None  # the stream ended and the segment agreed with itself
        return ReadBack(cast(FramesBlock, {**h.proof.block(), "timestamps_ns": h.timestamps_ns,
                                           "segments": h.segments}), h.xxh3)

    def writer(fid: str) -> Callable[[Iterable[SessionFrame]], BuiltCopy]:
        def write(frames: Iterable[SessionFrame]) -> BuiltCopy:
            out = partial / fid
            out.mkdir()
            return write_verified(fmts[fid], fid, frames, out, ctx, expected)
        return write

    try:
        outcomes = fan_out(source.frames(), [writer(fid) for fid in formats], copy=dataclasses.replace,
                           slots=usable_cores())
        damaged = next((o for o in outcomes if isinstance(o, SourceDamagedError)), None)
        if damaged is not None:
            raise damaged
        failures = []
        built: dict[str, BuiltCopy] = {}
        for fid, o in zip(formats, outcomes, strict=True):
            if isinstance(o, BaseException):
                raise o
            if o.problems:
                failures.append(f"{fid}: " + "; ".join(o.problems[:5]))
            built[fid] = o
        extras = source.extras.finish([seg]) if source.extras is not None else {"verified": False}
        if not extras.get("verified"):
            failures.append(f"extras: {extras.get('verification')}")
        if failures:
            raise VerificationError(f"{seg}: this segment's archive did not verify; nothing was kept", failures)
        summary.finish().save(partial / SUMMARY_NAME)
        h = source.hashes
        assert h is not None
        part = SegmentPart(segment, seg.stat().st_size, first_index, expected().frames, h.width, h.height,
                           {fid: {"files": b.files, "encode_s": b.encode_s, "decode_s": b.decode_s}
                            for fid, b in built.items()})
        (partial / PART_JSON).write_text(json.dumps(part.to_dict()))
        for p in partial.rglob("*"):
            if p.is_file():
                with open(p, "rb") as f:
                    os.fsync(f.fileno())
        final = parts / segment
        if final.exists():
            shutil.rmtree(final)
        os.replace(partial, final)
        fsync_dir(parts)
        return part
    except BaseException:
        if source.extras is not None:
            source.extras.abort()
        shutil.rmtree(partial, ignore_errors=True)
        raise


def finalize_session(session_dir: str | Path, formats: list[str] | tuple[str, ...] = DEFAULT_FORMATS) -> Manifest:
    """The session's archive from its segments' parts: manifest, final folders, extras, summary."""
    session_dir = Path(session_dir)
    formats = list(formats)
    if list(session_dir.glob(f"*{ACTIVE_SUFFIX}")):
        raise ArchiveError(f"{session_dir}: has unfinished segments (*.active); recording, or run `thermcap recover`")
    lock = lock_session(session_dir, "archiver", wait_s=60.0)
    if lock is None:
        raise ArchiveError(f"{session_dir}: {holder(session_dir) or 'another process'} holds this session")
    try:
        return _finalize_locked(session_dir, formats)
    finally:
        lock.release()


def _finalize_locked(session_dir: Path, formats: list[str]) -> Manifest:
    if _archived(session_dir, formats):  # another finalize got here first
        shutil.rmtree(parts_dir(session_dir), ignore_errors=True)
        return load_manifest(session_dir)
    segments = session_segments(session_dir)
    parts: list[SegmentPart] = []
    for seg in segments:
        part = _done_part(session_dir, seg, formats)
        if part is None:
            raise ArchiveError(f"{seg}: its segment task has not finished (no verified part for {', '.join(formats)})")
        parts.append(part)
    meta = read_session_meta(session_dir)
    session_id = meta.get("session_id", session_dir.name)
    manifest = load_manifest(session_dir, required=False) or new_manifest(session_id, meta)
    manifest["requested_formats"] = sorted(set(manifest.get("requested_formats", [])) | set(formats))
    # every part's digests are by DEFAULT_DIGEST (``_done_part``)
    frames = cast(FramesBlock, {**FrameProof(DEFAULT_DIGEST, [], []).block(), "timestamps_ns": [], "segments": []})
    for p in parts:
        for k in frames:
            frames[k] += p.frames[k]  # type: ignore[literal-required]
    proof = frame_proof(frames)
    known = frame_proof(manifest.get("frames"))
    if known.pixels and (known.name != proof.name or known.pixels != proof.pixels):
        # a rotted source must not replace the hashes it is checked against
        raise VerificationError(f"{session_dir}: the segments' frames differ from the manifest's hashes "
                                f"({known.name})", [])
    total = len(proof.pixels)
    sized = [p for p in parts if p.count]
    w, h = (sized[0].width, sized[0].height) if sized else (0, 0)
    manifest["frames"] = frames
    manifest["source"] = {"segments": [{"name": p.segment, "frames": p.count, "bytes": p.segment_bytes}
                                       for p in parts],
                          "frames": total, "width": w, "height": h, "raw_bytes": total * w * h * 2, "deleted": False}
    save_manifest(session_dir, manifest)
    pdir = parts_dir(session_dir)
    ctx = ArchiveContext(session_id=session_id, session_meta=meta, total_frames=total,
                         frames_per_segment={p.segment: p.count for p in parts})
    failures: list[str] = []
    for fid in formats:
        if manifest["formats"].get(fid, {}).get("verified") and (archive_dir(session_dir) / fid).is_dir():
            continue
        fmt = get_format(fid)
        partial = fresh_partial(session_dir, fid)
        built = _assemble(fmt, fid, [(pdir / p.segment / fid, p.formats[fid]) for p in parts], partial, ctx,
                          frames)
        entry = format_entry(fmt, built, total, manifest["source"]["raw_bytes"])
        problems = take_name(session_dir, fid, partial, manifest, entry)
        if problems:
            failures.append(f"{fid}: " + "; ".join(problems[:5]))
    if failures:
        raise VerificationError(f"{session_dir}: archive verification failed; the source was kept", failures)
    manifest["extras"] = _join_extras(session_dir, [pdir / p.segment for p in parts], segments)
    save_manifest(session_dir, manifest)
    if not manifest["extras"].get("verified"):
        failures.append(f"extras: {manifest['extras'].get('verification')}")
    if failures:
        raise VerificationError(f"{session_dir}: archive verification failed; the source was kept", failures)
    if not _summary_intact(archive_dir(session_dir), manifest):
        summary = _join_summaries([load_summary((pdir / p.segment / SUMMARY_NAME).read_bytes()) for p in parts])
        path = archive_dir(session_dir) / SUMMARY_NAME
        summary.save(path)
        manifest["summary"] = cast(SummaryEntry, {"path": SUMMARY_NAME, "bytes": path.stat().st_size,
                                                  ctx.digest: file_digest(path, ctx.digest),
                                                  "band_rows": summary.band_rows, "frames": summary.frames})
        save_manifest(session_dir, manifest)
    shutil.rmtree(pdir)  # everything they held is in the archive and its manifest now
    return manifest


def _assemble(fmt: Any, fid: str, parts: list[tuple[Path, dict[str, Any]]], out: Path, ctx: ArchiveContext,
              frames: FramesBlock) -> BuiltCopy:
    """One format's final folder from its verified parts."""
    proof = frame_proof(frames)
    assembled = fmt.assemble([(d, info["files"]) for d, info in parts], out, ctx)
    encode_s = sum(float(info["encode_s"]) for _, info in parts)
    if assembled is None:  # one file per segment: the verified bytes themselves
        files, problems = [], []
        for d, info in parts:
            for rec in info["files"]:
                src, dst = d / rec["path"], out / rec["path"]
                if dst.exists():
                    problems.append(f"{fid}/{rec['path']}: two segments give the same file name")
                    continue
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)
                problem = file_problem(dst, rec)
                if problem is not None:  # changed since its task verified it: that part is void
                    problems.append(f"{fid}/{rec['path']}: {problem} (as its segment task verified it); "
                                    f"the part was removed and its segment's task runs again")
                    shutil.rmtree(d.parent, ignore_errors=True)
                files.append(dict(rec))
        return BuiltCopy(files, problems, encode_s, sum(float(i["decode_s"]) for _, i in parts),  # type: ignore[arg-type]
                         f"bit-exact: every segment's files decoded with the format's reader match the MCAP "
                         f"source's pixels, sidecars and times ({proof.name}) in their segment's task, and are "
                         f"kept byte for byte ({len(proof.pixels)} frames)")
    files = assembled
    for rec in files:
        p = out / rec.path
        rec.bytes, rec.digest = p.stat().st_size, file_digest(p, ctx.digest)
    entries = [{"path": r.path, "frames": r.frames, "bytes": r.bytes, ctx.digest: r.digest} for r in files]
    problems, decode_s = verify_format_dir(fmt, out, entries, proof, where=fid, times=frames["timestamps_ns"])
    return BuiltCopy(entries, problems, encode_s, decode_s,  # type: ignore[arg-type]
                     f"bit-exact: assembled from the segments' compressed chunks, then {len(proof.pixels)} "
                     f"frames decoded with the format's reader match the MCAP source's pixels, sidecars and times "
                     f"({proof.name})")


def _join_extras(session_dir: Path, part_dirs: list[Path], segments: list[Path]) -> ExtrasEntry:
    """The parts' extras (each already compared with its segment) as one ``extras.mcap``,
    compared again with the whole source's attachments and metadata."""
    adir = archive_dir(session_dir)
    if (adir / EXTRAS_NAME).is_file():
        old = load_manifest(session_dir, required=False) or {}
        if (old.get("extras") or {}).get("verified"):
            return old["extras"]
    return extras_from(adir, [d / EXTRAS_NAME for d in part_dirs], segments)


def _join_summaries(parts: list[FrameSummary]) -> FrameSummary:
    parts = [p for p in parts if p.frames] or parts[:1]  # a segment may hold no frame of this camera
    first = parts[0]
    return FrameSummary(first.band_rows, first.width, first.height, np.concatenate([p.min for p in parts]),
                        np.concatenate([p.max for p in parts]), np.concatenate([p.sum for p in parts]),
                        np.concatenate([p.band_crc32 for p in parts]))


def iter_parts(session_dir: Path) -> Iterator[SegmentPart]:
    for p in sorted(parts_dir(session_dir).glob(f"*/{PART_JSON}")):
        yield SegmentPart.from_dict(json.loads(p.read_text()))
