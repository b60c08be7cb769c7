"""``thermcap cut``: part of a session, by time and topic, as one MCAP file (like ``mcap filter``),
from the MCAP source while it exists, else from the verified archive and its extras.mcap: the
same slicer ``GET /export.mcap`` streams."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CutResult", "cut_session"]


@dataclass(frozen=True)
class CutResult:
    out: Path
    bytes: int
    start_ns: int | None
    end_ns: int | None
    topics: list[str] | None


def cut_session(session_dir: Path, root: Path, out: Path, start: str | None, end: str | None,
                topics: list[str] | None) -> CutResult:
    import io

    from thermcap.archive.reading.mcap_slice import export_mcap, unreadable_segments
    from thermcap.recorder.cli.options import parse_instant
    from thermcap.recorder.storage.layout import SessionLayout
    from thermcap.recorder.storage.reader import session_segments
    from thermcap.session import LocalSession

    if out.exists():
        raise FileExistsError(f"{out} exists; thermcap does not overwrite a file (remove it or name another)")
    layout = SessionLayout.of(session_dir)
    if not layout.session_json.is_file() and not layout.manifest.is_file():
        raise ValueError(f"{session_dir}: not a session (no session.json or archive manifest)")
    session = LocalSession(session_dir, root)
    times = session.table.timestamp_ns
    first = int(times[0]) if len(times) else 0
    t0, t1 = parse_instant(start, first, "start"), parse_instant(end, first, "end")
    if t0 is not None and t1 is not None and t1 <= t0:
        raise ValueError("--end must be after --start")
    inside = np.ones(len(times), bool)
    if t0 is not None:
        inside &= np.asarray(times) >= t0
    if t1 is not None:
        inside &= np.asarray(times) < t1
    if len(times) and not inside.any():
        raise ValueError(f"no frame between {_when(t0, 'the start')} and {_when(t1, 'the end')}: the session's "
                         f"frames run from "
                         f"{_when(int(times[0]))} to {_when(int(times[-1]))}")
    if topics:
        known = _topics(session_dir)
        unknown = [t for t in topics if t not in known]
        if unknown:
            raise ValueError(f"no topic {', '.join(unknown)} in {session_dir.name} (its topics: "
                             f"{', '.join(sorted(known))})")
    unreadable = unreadable_segments(session_dir)
    if unreadable:
        raise ValueError(f"{session_dir}: {'; '.join(unreadable[:3])}; `thermcap recover {session_dir}` repairs a "
                         f"segment that was cut short")
    frames = extras = None
    if not session_segments(session_dir):
        reader = session.frames  # every frame through the checked reader, as `thermcap.open` reads them
        keep = [(int(i), int(t)) for i, t in zip(session.table.index, times, strict=True)
                if (t0 is None or t >= t0) and (t1 is None or t < t1)]
        frames = ((i, t, (lambda i=i: reader.pixels(i)), (lambda i=i: reader.sidecar(i))) for i, t in keep)
        path = SessionLayout.of(session_dir).extras
        if path.is_file():
            def extras() -> io.BufferedReader:
                return open(path, "rb")
    part = out.with_name(out.name + ".partial")
    try:
        with open(part, "xb") as f:
            for block in export_mcap(session_dir, t0, t1, topics, frames, extras):
                f.write(block)
            f.flush()
            os.fsync(f.fileno())
        part.replace(out)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    return CutResult(out, out.stat().st_size, t0, t1, topics)


def _when(t: int | None, otherwise: str = "") -> str:
    from thermcap.recorder.icd.names import iso_utc

    return otherwise if t is None else iso_utc(t)


def _topics(session_dir: Path) -> set[str]:
    """Every topic the session holds: its segments' channels, or once they are deleted the
    frames' topics and those of the archive's extras.mcap."""
    from mcap.reader import make_reader

    from thermcap.recorder.icd.topics import TOPIC_IMAGE, TOPIC_METADATA
    from thermcap.recorder.storage.layout import SessionLayout
    from thermcap.recorder.storage.reader import session_segments

    files = session_segments(session_dir) or [p for p in [SessionLayout.of(session_dir).extras] if p.is_file()]
    known = {TOPIC_IMAGE, TOPIC_METADATA}
    for path in files:
        try:
            with open(path, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:
            continue
        if summary is not None:
            known |= {c.topic for c in summary.channels.values()}
    return known
