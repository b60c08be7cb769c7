"""A session's one numbering of its frames, and each frame's sidecar placed in it.

Once a session is archived, the manifest's frame table (times, segments, digests) numbers its
frames for every copy, every reader and the index; before that, the MCAP source's frames in
order do. A frame's number never depends on which segments happened to be readable: a segment
that cannot be read leaves its frames' places empty (named in ``problems``), and a segment the
session's ledger lists that is gone with no record of why is named too, never counted around.
Each frame's sidecar comes from the cheapest copy that has it: a stored-ZIP archive's JSON
entries, the MCAP source, ``extras.mcap``, then any other verified format.

The index (``api.indexing``) and ``thermcap.open`` on a folder both number a session here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.archive.reading.frame_table import FRAME_FIELDS, FrameTable, field_array
from thermcap.archive.reading.zip_directory import ZIPPED_FORMATS, read_zip_file
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.quality import graded_contrast
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import TOPIC_METADATA
from thermcap.recorder.storage.digest import FrameProof, frame_proof
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.ledger import lost_segments
from thermcap.recorder.storage.manifest_file import read_manifest_file
from thermcap.recorder.storage.reader import session_segments

__all__ = ["NumberedFrames", "frame_table", "load_manifest_quietly", "number_frames", "sidecar_summary", "table_of",
           "verified_copies"]


@dataclass
class NumberedFrames:
    """Every frame of a session by its number: time, segment (None once only the archive holds
    it) and sidecar, with the manifest's digests (``proof``) and what could not be read."""

    manifest: dict[str, Any] | None
    proof: FrameProof
    sidecars: list[dict[str, Any]]
    times: list[int]
    segments: list[str | None]
    problems: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.times)


def frame_table(session_id: str, numbered: NumberedFrames) -> FrameTable:
    """The numbered frames as columns: time and sidecar summary (``FRAME_FIELDS``) per frame."""
    return table_of(session_id, numbered.times, numbered.sidecars)


def table_of(session_id: str, times: list[int], sidecars: list[dict[str, Any]]) -> FrameTable:
    """Frames ``0..n-1`` at ``times`` with their sidecars' summaries (blank where a sidecar is
    missing: ``sidecars`` shorter than ``times``)."""
    rows = [sidecar_summary(sidecars[i] if i < len(sidecars) else {}) for i in range(len(times))]
    fields = {name: field_array(name, [r[col] for r in rows]) for name, (col, _, _) in FRAME_FIELDS.items()}
    return FrameTable(session_id, np.arange(len(times), dtype=np.int64), np.array(times, np.int64), fields)


def verified_copies(manifest: dict[str, Any] | None) -> dict[str, Any]:
    """The archive formats a reader may take frames from: verified, and not marked damaged by
    scrub (until ``scrub --repair`` rebuilt and re-verified them)."""
    return {f: e for f, e in (manifest or {}).get("formats", {}).items() if e.get("verified") and not e.get("damaged")}


def number_frames(session_dir: Path, problems: list[str] | None = None) -> NumberedFrames:
    """The session's frames in its one numbering. Reads only: nothing is written anywhere."""
    problems = [] if problems is None else problems
    manifest = load_manifest_quietly(session_dir)
    verified = verified_copies(manifest)
    sidecars: list[dict]
    times: list[int]
    segs: list[str | None]
    if (manifest or {}).get("frames", {}).get("timestamps_ns"):
        sidecars, times, segs = _sidecars_by_manifest(session_dir, manifest or {}, verified, problems)
    else:  # not archived: the source's frames in its order, at their log times (as the manifest keeps them)
        times = []
        sidecars, names = _sidecars_from_mcap(session_segments(session_dir), problems, times)
        segs = list(names)
    for lost in lost_segments(session_dir):
        problems.append(f"{lost.name}: {lost.frames} frames session.json lists are gone from the folder with no "
                        f"record of why (not evicted, freed, archived or set aside)")
    analysed = SessionLayout.of(session_dir).analysis_jsonl
    if analysed.is_file():  # `thermcap analyze` results take precedence over the recorded sidecars
        by_index = {}
        with open(analysed) as f:
            for line in f:
                row = json.loads(line)
                by_index[row["index"]] = row
        sidecars = [{**sc, **{k: by_index[i][k] for k in ("thermal_analysis", "targets")}} if i in by_index else sc
                    for i, sc in enumerate(sidecars)]
    return NumberedFrames(manifest, frame_proof((manifest or {}).get("frames")), sidecars, times, segs, problems)


def load_manifest_quietly(session_dir: Path) -> dict[str, Any] | None:
    """The manifest, or None where there is none or it cannot be read (the ``manifest``
    module's own loader says why, for the commands that must stop on it)."""
    try:
        return read_manifest_file(session_dir)
    except McapFileError:
        return None


def _sidecars_from_zip(session_dir: Path, fmt: str, files: list[dict[str, Any]]) -> list[dict]:
    """The sidecars of a zipped archive, in session order, from its JSON entries. Where each frame
    sits is not copied into the index: the ZIP's own central directory says it
    (``api.reading.zip_index``)."""

    sidecars = []
    for rec in files:
        path = SessionLayout.of(session_dir).format_dir(fmt) / rec["path"]
        entries = read_zip_file(path)
        with open(path, "rb") as f:
            for off, n in zip(entries.sidecar_offset, entries.sidecar_length, strict=True):
                f.seek(int(off))
                sidecars.append(json.loads(f.read(int(n)) or b"{}"))
    return sidecars


def _sidecars_from_mcap(files: list[Path], problems: list[str] | None = None,
                        log_times: list[int] | None = None) -> tuple[list[dict], list[str]]:
    """Every readable sidecar of ``files``, chunk by chunk: a damaged chunk or a segment with no
    readable summary hides only itself (named in ``problems``), never the rest of the session.
    Each one's log time goes to ``log_times``, when given: where it sits in the session."""
    log_times = [] if log_times is None else log_times
    from thermcap.recorder.storage.chunks import SegmentIndex, message_records, read_chunk, read_through

    out, segs = [], []
    for seg in files:
        try:
            index = SegmentIndex.load(seg)
        except McapFileError as exc:
            if problems is None:
                raise
            problems.append(f"{seg.name}: {exc} (`thermcap recover {seg}` keeps every intact chunk)")
            continue
        if index is None or not index.chunks_in_time_order or TOPIC_METADATA not in index.topics:
            try:  # written without a chunk index (or with none at all): read through
                for _, ch, msg in read_through(seg, [TOPIC_METADATA]):
                    out.append(json.loads(json_payload(ch.message_encoding, msg.data)))
                    segs.append(seg.name)
                    log_times.append(msg.log_time)
            except McapFileError as exc:
                if problems is None:
                    raise
                problems.append(f"{seg.name}: {exc} (`thermcap recover {seg}` keeps every intact chunk)")
            continue
        cid = index.topics[TOPIC_METADATA]
        channel = index.channels[cid]
        for chunk in range(len(index.offsets)):
            try:
                records = read_chunk(index, chunk)
            except McapFileError as exc:
                if problems is None:
                    raise
                problems.append(f"{seg.name}: {exc}; its frames are not served until `thermcap recover {seg}`")
                continue
            view = memoryview(records.data)
            for t, _channel, _seq, _pub, start, stop in sorted(
                    (m for m in message_records(records) if m[1] == cid), key=lambda m: m[0]):
                out.append(json.loads(json_payload(channel.message_encoding, bytes(view[start:stop]))))
                segs.append(seg.name)
                log_times.append(t)
    return out, segs


def _sidecars_by_manifest(session_dir: Path, manifest: dict[str, Any], verified: dict[str, Any],
                          problems: list[str]) -> tuple[list[dict], list[int], list[str | None]]:
    """Each frame of the manifest's table with its sidecar, taken from the cheapest copy that has
    it: a stored-ZIP archive (its JSON entries), the MCAP source (placed by segment and log time,
    so a segment that cannot be read leaves its frames' places empty, never shifts the others),
    ``extras.mcap``, then any other verified format read in order. A copy that fails is named in
    ``problems`` and passed over; a frame no copy gives keeps its place and time, its summary blank."""
    from thermcap.archive.reading.whole import frames_from_format, verified_formats

    frames_meta = manifest.get("frames", {})
    times: list[int] = [int(t) for t in frames_meta.get("timestamps_ns") or []]
    segs: list[str | None] = list(frames_meta.get("segments") or [None] * len(times))
    n = len(times)
    got: dict[int, dict] = {}
    layout = SessionLayout.of(session_dir)
    on_disk = session_segments(session_dir)
    for fmt in (f for f in ZIPPED_FORMATS if f in verified and layout.format_dir(f).is_dir()):
        try:
            from_zip = _sidecars_from_zip(session_dir, fmt, verified[fmt]["files"])
        except Exception as exc:  # a damaged ZIP fails anywhere in its directory or entries
            problems.append(f"archive/{fmt}: {type(exc).__name__}: {exc}; its copy is passed over (`thermcap scrub "
                            f"--repair` rebuilds it from another)")
            continue
        if len(from_zip) == n:
            got = dict(enumerate(from_zip))
            break
        problems.append(f"archive/{fmt}: {len(from_zip)} sidecars for the manifest's {n} frames; passed over")
    if len(got) < n and on_disk:
        place = {(seg, t): i for i, (seg, t) in enumerate(zip(segs, times, strict=True))}
        log_times: list[int] = []
        found, names = _sidecars_from_mcap(on_disk, problems, log_times)
        for sc, seg, t in zip(found, names, log_times, strict=True):
            i = place.get((seg, t))
            if i is not None:
                got.setdefault(i, sc)
    if len(got) < n and layout.extras.is_file():
        try:
            extra, _ = _sidecars_from_mcap([layout.extras], problems)
        except McapFileError as exc:
            problems.append(f"archive/extras.mcap: {exc}")
            extra = []
        if len(extra) == n:
            for i, sc in enumerate(extra):
                got.setdefault(i, sc)
    if len(got) < n:
        for fmt in verified_formats(manifest, layout):  # type: ignore[arg-type]
            try:
                for frame in frames_from_format(manifest, layout, fmt):  # type: ignore[arg-type]
                    if frame.index not in got:
                        got[frame.index] = json.loads(frame.sidecar or b"{}")
                    if len(got) == n:
                        break
            except Exception as exc:  # a damaged copy stops here; the next one may hold the rest
                problems.append(f"archive/{fmt}: {type(exc).__name__}: {exc}")
            if len(got) == n:
                break
    if len(got) < n:
        problems.append(f"{n - len(got)} frames' sidecars could not be read from any copy: listed at their times, "
                        f"their summaries blank")
    sidecars = [got.get(i, {}) for i in range(n)]
    # segments the archive does not cover yet (archived while more was recorded): after its frames
    covered = set(segs)
    newer = [seg for seg in on_disk if seg.name not in covered]
    if newer:
        log_times = []
        found, names = _sidecars_from_mcap(newer, problems, log_times)
        sidecars += found
        segs += list(names)
        times += log_times
    return sidecars, times, segs


def sidecar_summary(sc: dict[str, Any]) -> dict[str, Any]:
    """A frame's searchable summary, by the index's column names (``FRAME_FIELDS`` reads them)."""
    ta = sc.get("thermal_analysis") or {}
    targets = sc.get("targets") or []
    # an unanalysed frame, or one with no target, has no grade (0.0 is a placeholder)
    return {"grade": graded_contrast(ta), "slew_to_cue": bool((sc.get("slew_to_cue") or {}).get("slew_to_cue_active")),
            "target_count": len(targets),
            "max_target_temp_c": max((t["max_temp_c"] for t in targets), default=None)}
