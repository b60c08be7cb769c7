"""``thermcap archive``: repack a recorded session losslessly, prove it, and record the proof.

For each requested format: write into ``archive/<format>.partial/``, decode every frame back
with the format's ordinary reader and compare its digest with the MCAP source's, fsync, and only
then rename the folder to ``archive/<format>/`` and add it to the manifest. A crash leaves at
most a ``.partial`` folder, which no reader treats as an archive and the next run replaces;
formats already verified are skipped, so re-running finishes the job. The MCAP source is deleted
(``--delete-source``) only when every requested format verified.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from thermcap.archive.codecs import library_versions
from thermcap.archive.evidence import copy_problems, extras_problems, local_cover
from thermcap.archive.exceptions import ArchiveError, SourceDamagedError, VerificationError
from thermcap.archive.extras import ExtrasWriter
from thermcap.archive.fanout import fan_out
from thermcap.archive.formats import ArchiveContext, ArchiveFormat, FileRecord, get_format
from thermcap.archive.frame_summary import SUMMARY_NAME, SummaryBuilder
from thermcap.archive.manifest import (
    DEFAULT_DIGEST,
    DIGESTS,
    FrameProof,
    archive_dir,
    file_digest,
    file_matches,
    frame_proof,
    iso_now,
    load_manifest,
    new_manifest,
    record_digest,
    save_manifest,
)
from thermcap.archive.manifest_types import FileEntry, FormatEntry, FramesBlock, Manifest, SummaryEntry
from thermcap.archive.read_back import ReadBack
from thermcap.archive.source_pass import SourcePass
from thermcap.recorder.frame_heap import keep_frame_blocks
from thermcap.recorder.storage.atomic import fsync_dir, fsync_tree
from thermcap.recorder.storage.layout import PARTIAL_SUFFIX, SessionLayout
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import SessionFrame, count_frames, read_session_meta, session_segments
from thermcap.recorder.storage.ring import load_windows
from thermcap.recorder.storage.rosbag2 import write_bag_metadata
from thermcap.recorder.storage.segments import ACTIVE_SUFFIX

__all__ = ["DEFAULT_FORMATS", "PARTIAL_SUFFIX", "BuiltCopy", "archive_session", "build_format", "encoder_threads",
           "format_entry", "fresh_partial", "take_name", "usable_cores", "verify_format_dir", "write_verified"]

from thermcap.archive.defaults import DEFAULT_FORMATS


def usable_cores() -> int:
    """The cores this process may run on (its affinity, which a container or taskset narrows)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def encoder_threads(total: int | None, formats_at_once: int) -> int:
    """Each format's encoder threads when ``formats_at_once`` are written side by side, from
    ``total`` threads in all (None: the usable cores). The formats are already parallel to each
    other: three formats with two threads each on two cores cost 4% more CPU than with one each
    (17.4 against 18.1 ms a 640x512 frame, the same wall time), where one format alone gains
    from both cores."""
    total = usable_cores() if total is None else total
    return max(1, total // max(1, formats_at_once))


def _summary_intact(adir: Path, manifest: Manifest) -> bool:
    entry = manifest.get("summary") or {}
    return file_matches(adir / entry.get("path", SUMMARY_NAME), entry)


def verify_format_dir(fmt: ArchiveFormat, out_dir: Path, files: Sequence[Mapping[str, Any]],
                      proof: FrameProof, *, where: str, times: list[int] | None = None, hash_files: bool = True,
                      digest: tuple[str, Callable[[np.ndarray], str | bytes], Sequence[str | bytes]] | None = None,
                      workers: int = 2) -> tuple[list[str], float]:
    """Decode every file with the format's reader and compare each frame's pixels, sidecar and
    time with the source's digests (``proof``); return (problems, decode seconds). Its sidecars and
    ``times`` are absent only in manifests written before they were recorded. ``hash_files=False``
    where the caller has just hashed the files to make their entries (the writer's own check),
    which may also compare pixels by another ``digest`` (name, function, each frame's) of the same
    source read (see ``read_back``). ``workers``: the reader's threads (``ArchiveFormat.read``)."""
    digest_name, pixel_digest, expected = digest if digest is not None else (proof.name, proof.of_pixels,
                                                                              proof.pixels)
    sidecars = proof.sidecars
    problems: list[str] = []
    index = 0
    decode_s = 0.0
    for rec in files:
        path = out_dir / rec["path"]
        if not path.is_file():
            problems.append(f"{where}/{rec['path']}: missing")
            index += rec["frames"]
            continue
        named = record_digest(rec) if hash_files else None
        if named is not None and file_digest(path, named[0]) != named[1]:
            problems.append(f"{where}/{rec['path']}: file {named[0]} differs from the manifest")
        got = 0
        t = time.perf_counter()
        try:
            for frame in fmt.read(out_dir, [rec["path"]], workers=workers):
                i = index + got
                if i >= len(expected):
                    problems.append(f"{where}/{rec['path']}: holds more frames than the session ({i + 1}+)")
                    break
                if pixel_digest(frame.pixels) != expected[i]:
                    problems.append(f"frame {i} ({where}/{rec['path']}): {digest_name} differs")
                if sidecars and proof.of_sidecar(frame.sidecar) != sidecars[i]:
                    problems.append(f"frame {i} ({where}/{rec['path']}): sidecar differs from the source's")
                if times and frame.log_time is not None and frame.log_time != times[i]:
                    problems.append(f"frame {i} ({where}/{rec['path']}): time {frame.log_time} differs from "
                                    f"the source's {times[i]}")
                elif times and frame.log_time is None:
                    problems.append(f"frame {i} ({where}/{rec['path']}): no time stored")
                got += 1
        except Exception as exc:  # corrupt data may fail anywhere inside a third-party decoder
            problems.append(f"{where}/{rec['path']}: cannot decode after {got} frames ({type(exc).__name__}: {exc})")
        decode_s += time.perf_counter() - t
        if got != rec["frames"] and not any(rec["path"] in p for p in problems[-1:]):
            problems.append(f"{where}/{rec['path']}: {got} frames decoded, {rec['frames']} expected")
        index += rec["frames"]
    if index != len(expected):
        problems.append(f"{where}: files hold {index} frames, the session has {len(expected)}")
    return problems, decode_s


#: Formats are written on parallel threads (see fan_out); they share the manifest and its file.
_MANIFEST_LOCK = threading.Lock()


@dataclasses.dataclass
class BuiltCopy:
    """A format's files written and checked in a folder that has not taken its final name yet."""

    files: list[FileEntry]
    problems: list[str]
    encode_s: float
    decode_s: float
    verification: str = ""


def write_verified(fmt: ArchiveFormat, fid: str, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext,
                   expected: Callable[[], ReadBack]) -> BuiltCopy:
    """Write ``frames`` into ``out_dir`` and decode every file back with the format's reader,
    comparing each frame with ``expected()`` (called once the stream has ended: the single read
    of the source gives the hashes only then). A writer or source failure removes ``out_dir``."""
    keep_frame_blocks()  # the codecs' batch-sized temporaries: see recorder.frame_heap
    t = time.perf_counter()
    try:
        records: list[FileRecord] = fmt.write(frames, out_dir, ctx)
    except BaseException:  # the source failed (or the writer): no half-written copy is left behind
        shutil.rmtree(out_dir, ignore_errors=True)
        raise
    encode_s = time.perf_counter() - t
    for rec in records:
        p = out_dir / rec.path
        rec.bytes = p.stat().st_size
        rec.digest = file_digest(p, ctx.digest)
    files = [cast(FileEntry, {"path": r.path, "frames": r.frames, "bytes": r.bytes, ctx.digest: r.digest})
             for r in records]
    back = expected()
    proof = back.proof
    name, digest, pixels = back.pixel_digest
    # read back on the format's share of the cores, as it was written: three formats verifying
    # at once on two cores with two reader threads each cost 16.12 against 15.65 CPU ms a frame
    # for the whole archive, and no wall time (1.81 against 1.86x real time; medians of 8, 2026-12-06)
    problems, decode_s = verify_format_dir(fmt, out_dir, files, proof, where=fid,
                                           times=back.frames.get("timestamps_ns"), hash_files=False,
                                           digest=(name, digest, pixels), workers=ctx.workers)
    how = (f"the pixels by xxh3-128 taken on the same read as the manifest's {proof.name}" if name == "xxh3-128"
           else f"the pixels by the manifest's {proof.name}")
    return BuiltCopy(files, problems, encode_s, decode_s,
                     f"bit-exact: {len(proof.pixels)} frames decoded with the format's reader match the MCAP "
                     f"source's pixels, sidecars and times ({how}; sidecars by {proof.name})")


def format_entry(fmt: ArchiveFormat, built: BuiltCopy, frames: int, raw_bytes: int) -> FormatEntry:
    total_bytes = sum(int(f["bytes"]) for f in built.files)
    return {
        "config": fmt.get_config(), "description": fmt.description, "files": built.files,
        "frames_per_file": [int(f["frames"]) for f in built.files], "objects": len(built.files),
        "bytes": total_bytes, "compression_ratio": round(raw_bytes / total_bytes, 4) if total_bytes else None,
        "bits_per_pixel": round(total_bytes * 8 / (raw_bytes / 2), 4) if raw_bytes else None,
        "encode_fps": round(frames / built.encode_s, 1) if built.encode_s else None,
        "decode_fps": round(frames / built.decode_s, 1) if built.decode_s else None,
        "library_versions": library_versions(), "verified": not built.problems, "verified_at": iso_now(),
        "verification": built.verification if not built.problems else built.problems[:100],
    }


def take_name(session_dir: Path, fid: str, partial: Path, manifest: Manifest, entry: FormatEntry) -> list[str]:
    """A checked copy takes its final name (replacing an older one only now) and its manifest
    entry; a failed one is removed and recorded as failed. Returns the problems."""
    adir = archive_dir(session_dir)
    final = adir / fid
    if not entry["verified"]:
        shutil.rmtree(partial)  # a failed archive never takes the final name
        with _MANIFEST_LOCK:
            if not manifest["formats"].get(fid, {}).get("verified"):
                manifest["formats"][fid] = {**entry, "files": [], "bytes": 0}
                save_manifest(session_dir, manifest)
        v = entry["verification"]
        return list(v) if isinstance(v, list) else [str(v)]
    fsync_tree(partial)
    if final.exists():  # replace the old copy (--force, or a damaged one) only now that the new one verified
        old = adir / (fid + ".old")
        if old.exists():
            shutil.rmtree(old)
        os.replace(final, old)
        os.replace(partial, final)
        shutil.rmtree(old)
    else:
        os.replace(partial, final)
    fsync_dir(adir)
    with _MANIFEST_LOCK:
        manifest["formats"][fid] = entry
        save_manifest(session_dir, manifest)
    return []


def _mark_damaged(session_dir: Path, manifest: Manifest, found: dict[str, list[str]]) -> None:
    """A copy recorded as verified whose files no longer hash as the manifest says is marked
    damaged (as scrub would), so no reader, gc or later step counts it before it is rebuilt."""
    changed = False
    for fid, problems in found.items():
        entry = manifest["formats"][fid]
        if not entry.get("damaged"):
            entry["damaged"] = {"at": iso_now(), "problems": problems[:20]}
            changed = True
    if changed:
        save_manifest(session_dir, manifest)


def fresh_partial(session_dir: Path, fid: str) -> Path:
    partial = archive_dir(session_dir) / (fid + PARTIAL_SUFFIX)
    if partial.exists():  # left by a crashed run; never taken for an archive
        shutil.rmtree(partial)
    partial.mkdir()
    return partial


def build_format(session_dir: Path, fid: str, fmt: ArchiveFormat, frames: Iterable[SessionFrame],
                 manifest: Manifest, meta: dict[str, Any], per_segment: dict[str, int], *, workers: int = 2,
                 on_progress: Callable[[str, int, int], None] | None = None,
                 read_back_xxh3: Callable[[], list[bytes] | None] | None = None,
                 digest: str = DEFAULT_DIGEST) -> list[str]:
    """Write ``frames`` as format ``fid`` into ``<fid>.partial``, verify every frame against the
    manifest's hashes, and only then take the final name (replacing an older copy only now) and
    record it in the manifest. Returns the problems; a failed copy never takes the final name.
    The archiver feeds it the MCAP source (and ``read_back_xxh3``, the digests its read took,
    when it took the manifest's hashes on that read); ``scrub --repair`` any verified copy.
    ``digest``: the hash its files are recorded by."""
    session_id = manifest.get("session_id", session_dir.name)
    total = sum(per_segment.values())
    partial = fresh_partial(session_dir, fid)
    done = [0]

    def tick() -> None:
        done[0] += 1
        if on_progress and done[0] % 16 == 0:
            on_progress(f"writing {fid}", done[0], total)

    ctx = ArchiveContext(session_id=session_id, session_meta=meta, total_frames=total,
                         frames_per_segment=per_segment, workers=workers, on_frame=tick, digest=digest)

    def expected() -> ReadBack:
        # read only now: the archiver's single read of the source gives the manifest its hashes
        # when the frame stream ends, which is before any writer returns
        if on_progress:
            on_progress(f"verifying {fid}", 0, total)
        return ReadBack(manifest["frames"], read_back_xxh3() if read_back_xxh3 is not None else None)

    built = write_verified(fmt, fid, frames, partial, ctx, expected)
    entry = format_entry(fmt, built, len(frame_proof(manifest["frames"]).pixels), manifest["source"]["raw_bytes"])
    return take_name(session_dir, fid, partial, manifest, entry)


def archive_session(session_dir: str | Path, formats: list[str] | tuple[str, ...] = DEFAULT_FORMATS, *,
                    delete_source: bool = False, workers: int | None = None, force: bool = False,
                    on_progress: Callable[[str, int, int], None] | None = None,
                    before_delete: Callable[[Path], None] | None = None, digest: str = DEFAULT_DIGEST) -> Manifest:
    """Archive one session; returns the manifest. Raises VerificationError if any format fails.

    ``digest``: the hash of the manifest's proofs it takes now (each frame's pixels and sidecar,
    each file written); digests an earlier run recorded stay what copies are compared with, under
    the hash they name (``recorder.storage.digest``).

    ``workers``: encoder threads in all (None: the usable cores), shared among the formats
    written at once (``encoder_threads``); where the formats outnumber them, they take turns
    (``fan_out``'s slots), so ``workers=1`` never encodes two formats at once.

    ``before_delete(session_dir)`` runs once the copies are re-checked and before the source goes
    (the API indexes the archive there, so no reader is left pointing at deleted segments)."""
    session_dir = Path(session_dir)
    if digest not in DIGESTS:
        raise ArchiveError(f"--digest {digest}: thermcap archives by {' or '.join(DIGESTS)}")
    if not session_dir.is_dir():
        raise ArchiveError(f"{session_dir}: no such session folder")
    if list(session_dir.glob(f"*{ACTIVE_SUFFIX}")):
        raise ArchiveError(f"{session_dir}: has unfinished segments (*.active); recording, or run `thermcap recover`")
    lock = lock_session(session_dir, "archiver")
    if lock is None:
        raise ArchiveError(f"{session_dir}: {holder(session_dir) or 'another process'} holds this session")
    try:
        return _archive_locked(session_dir, list(formats), delete_source, workers, force, on_progress,
                               before_delete, digest)
    except OSError as exc:  # a read-only or full disk: name the file; the source is untouched
        raise ArchiveError(f"{exc.filename or session_dir}: {exc.strerror or exc}; nothing was deleted") from None
    finally:
        lock.release()


def _archive_locked(session_dir: Path, formats: list[str], delete_source: bool, workers: int | None, force: bool,
                    on_progress: Callable[[str, int, int], None] | None,
                    before_delete: Callable[[Path], None] | None = None, digest: str = DEFAULT_DIGEST) -> Manifest:
    meta = read_session_meta(session_dir)
    if isinstance(meta.get("cameras"), dict):  # read as one camera it would archive no frame at all
        split = meta.get("split_into")
        raise ArchiveError(
            f"{session_dir}: a session of several cameras ({', '.join(sorted(meta['cameras']))}); "
            + (f"it was split into {', '.join(sorted(split.values()))}: archive those" if split else
               f"`thermcap split-cameras {session_dir}` makes one session per camera (bit-exact), which archive "
               f"as any other; nothing was changed"))
    session_id = meta.get("session_id", session_dir.name)
    manifest = load_manifest(session_dir, required=False) or new_manifest(session_id, meta)
    # What the user asked for: gc and scrub count a session as covered only when all of it verified.
    manifest["requested_formats"] = sorted(set(manifest.get("requested_formats", [])) | set(formats))
    adir = archive_dir(session_dir)
    adir.mkdir(exist_ok=True)
    fmts = {fid: get_format(fid) for fid in formats}  # unknown ids fail before any work
    for left in adir.glob(f"*{PARTIAL_SUFFIX}"):  # a killed run's; never an archive, and we hold the lock
        shutil.rmtree(left) if left.is_dir() else left.unlink()

    segments = session_segments(session_dir)
    source_gone = bool(manifest.get("source", {}).get("deleted"))
    layout = SessionLayout.of(session_dir)
    # a format counts as done only if its files hash as the manifest says now (not on its flag)
    found = {f: copy_problems(layout, f, manifest["formats"].get(f)) for f in formats}
    todo = [f for f in formats if force or found[f]]
    _mark_damaged(session_dir, manifest, {f: p for f, p in found.items()
                                           if p and manifest["formats"].get(f, {}).get("verified")})
    if todo and (source_gone or not segments):
        why = "; ".join(p for f in todo for p in found[f][:2]) or "asked to rewrite"
        raise ArchiveError(f"{session_dir}: the MCAP source is gone; cannot write {', '.join(todo)} ({why}); "
                           f"`thermcap scrub --repair` rebuilds a damaged copy from another verified one")
    need_extras = bool(segments) and not source_gone and (
        force or bool(todo) or bool(extras_problems(layout, manifest.get("extras"))))
    per_segment = count_frames(session_dir) if todo or need_extras else {}
    total = sum(per_segment.values())
    known = frame_proof(manifest["frames"])
    # hashes already in the manifest stay what every copy is compared with (a source that rotted
    # since then fails verification instead of being hashed again as good)
    source = SourcePass(session_dir, per_segment, digest=digest,
                        hash_frames=bool(todo) and (not known.pixels or len(known.pixels) != total
                                                    or known.sidecar_key not in manifest["frames"]),
                        extras=ExtrasWriter(adir, digest) if need_extras else None,
                        # taken only with formats to write: they verify the very frames it summarises
                        summary=SummaryBuilder(total) if todo and (force or not _summary_intact(adir, manifest))
                        else None)

    def frames() -> Iterator[SessionFrame]:
        yield from source.frames()
        hashes = source.hashes  # the stream ended and the source agreed with itself
        if hashes is not None:
            with _MANIFEST_LOCK:
                manifest["frames"] = cast(FramesBlock, {**hashes.proof.block(), "timestamps_ns": hashes.timestamps_ns,
                                                        "segments": hashes.segments})
                manifest["source"] = {"segments": [{"name": s.name, "frames": per_segment[s.name],
                                                    "bytes": s.stat().st_size} for s in segments],
                                      "frames": total, "width": hashes.width, "height": hashes.height,
                                      "raw_bytes": total * hashes.width * hashes.height * 2, "deleted": False}
                save_manifest(session_dir, manifest)

    failures: list[str] = []
    # --workers: the encoder threads in all, and as many codecs working at once (fan_out's slots)
    threads = usable_cores() if workers is None else workers
    per_format = encoder_threads(threads, len(todo))

    # The source is decoded once and teed to every format's writer (each on its own thread), and
    # its other messages go to the extras from the same read; each format is still verified on
    # its own, by its own reader, before it takes its name.
    def writer_for(fid: str) -> Callable[[Iterable[SessionFrame]], list[str]]:
        def write(frames: Iterable[SessionFrame]) -> list[str]:
            return build_format(session_dir, fid, fmts[fid], frames, manifest, meta, per_segment,
                                workers=per_format, on_progress=on_progress, digest=digest,
                                read_back_xxh3=lambda: source.hashes.xxh3 if source.hashes is not None else None)
        return write

    try:
        if todo:
            outcomes = fan_out(frames(), [writer_for(fid) for fid in todo], copy=dataclasses.replace,
                               slots=threads)  # the codecs take turns on the threads (see fan_out)
        else:
            outcomes = []
            if source.extras is not None:
                for _ in frames():  # the extras alone
                    pass
        damaged = next((o for o in outcomes if isinstance(o, SourceDamagedError)), None)
        if damaged is not None:
            raise damaged
        for fid, outcome in zip(todo, outcomes, strict=True):
            if isinstance(outcome, ArchiveError | OSError):
                failures.append(f"{fid}: {outcome}")
            elif isinstance(outcome, BaseException):
                raise outcome
            elif outcome:
                failures.append(f"{fid}: " + "; ".join(outcome[:5]))
    except BaseException:  # nothing half-made is left behind: no extras.mcap.partial
        if source.extras is not None:
            source.extras.abort()
        raise

    if source.extras is not None:
        if on_progress:
            on_progress("keeping extras (attachments, metadata, other topics)", 0, 1)
        manifest["extras"] = source.extras.finish(segments)
        save_manifest(session_dir, manifest)
        if not manifest["extras"]["verified"]:
            failures.append(f"extras: {manifest['extras']['verification']}")
    if failures:
        raise VerificationError(f"{session_dir}: archive verification failed; the source was kept", failures)
    if source.summary is not None and source.summary.n == len(frame_proof(manifest["frames"]).pixels):
        path = adir / SUMMARY_NAME
        source.summary.finish().save(path)
        manifest["summary"] = cast(SummaryEntry, {"path": SUMMARY_NAME, "bytes": path.stat().st_size,
                                                  digest: file_digest(path, digest),
                                                  "band_rows": source.summary.band_rows, "frames": source.summary.n})
        save_manifest(session_dir, manifest)
    if delete_source:
        # the last copy goes only on evidence checked now: every file hashed against the manifest
        cover = local_cover(layout, manifest, formats)
        if not cover.ok:
            raise ArchiveError(f"refusing to delete the source: {'; '.join(cover.problems[:5])}")
        windows = load_windows(session_dir)
        if windows:  # an event window is kept as recorded, beside its verified archive
            manifest["source"]["kept_because"] = f"{len(windows)} event windows are protected (protected.json)"
            save_manifest(session_dir, manifest)
            return manifest
        if before_delete is not None:
            before_delete(session_dir)
        for seg in segments:
            seg.unlink()
        fsync_dir(session_dir)
        with contextlib.suppress(OSError):  # derived data: a failure must not undo the work above
            write_bag_metadata(session_dir)
        manifest["source"]["deleted"] = True
        manifest["source"]["deleted_at"] = iso_now()
        save_manifest(session_dir, manifest)
    return manifest
