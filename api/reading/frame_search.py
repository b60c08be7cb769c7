"""Frames across every session, hottest target first, from ``target_seconds`` alone.

A row holds one second of one session that has a frame with a target: the second's hottest
target (the row's rank in the search's index), its coolest, its lowest grade, and its frames with a target
packed as ``HOT_FRAME`` records. A search walks the rows from the hottest down, unpacks each, and
keeps the frames that pass; it stops once it holds a page and the next row's hottest target is
below the page's last, since no frame in a later row can rank above it. Every frame that passes
is found and the order is exact: the rows only decide how much is read.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import and_, or_, select
from sqlalchemy.engine import Connection

from thermcap.api import db
from thermcap.api.reading.frame_columns import FrameColumns

__all__ = ["HOT_FRAME", "FoundFrame", "search_targets", "target_second_rows"]

#: One frame with a target, as ``target_seconds.frames`` packs it: 26 bytes (a camera-hour with a
#: target in every frame is 5.6 MB).
HOT_FRAME = np.dtype([("idx", "<u4"), ("offset_ns", "<u4"), ("target_count", "<u2"),
                      ("max_target_temp_c", "<f8"), ("grade", "<f8")])


def target_second_rows(cols: FrameColumns) -> list[dict[str, Any]]:
    """The session's ``target_seconds`` rows: one per second with a frame with a target."""
    hot = np.flatnonzero(~np.isnan(cols.max_target_temp_c))
    if not len(hot):
        return []
    ts = cols.timestamp_ns[hot]
    second = ts // 1_000_000_000
    order = np.argsort(second, kind="stable")
    hot, second, ts = hot[order], second[order], ts[order]
    records = np.zeros(len(hot), HOT_FRAME)
    records["idx"] = hot
    records["offset_ns"] = ts - second * 1_000_000_000
    records["target_count"] = np.minimum(cols.target_count[hot], np.iinfo(np.uint16).max)
    records["max_target_temp_c"] = cols.max_target_temp_c[hot]
    records["grade"] = cols.grade[hot]
    starts = np.flatnonzero(np.r_[True, second[1:] != second[:-1]])
    rows = []
    for a, b in zip(starts, [*starts[1:], len(hot)], strict=True):
        part = records[a:b]
        graded = part["grade"][~np.isnan(part["grade"])]
        rows.append({"session_id": cols.session_id, "second": int(second[a]),
                     "max_target_temp_c": float(part["max_target_temp_c"].max()),
                     "min_target_temp_c": float(part["max_target_temp_c"].min()),
                     "min_grade": float(graded.min()) if len(graded) else None, "frames": part.tobytes()})
    return rows


@dataclass(frozen=True)
class FoundFrame:
    session_id: str
    idx: int
    timestamp_ns: int
    grade: float | None
    target_count: int
    max_target_temp_c: float

    def rank(self) -> tuple[float, str, int]:
        return (-self.max_target_temp_c, self.session_id, self.idx)


def _frames_of(row: Any, min_target_c: float | None, max_grade: float | None,
               after: tuple[float, str, int] | None) -> Iterable[FoundFrame]:
    rec = np.frombuffer(row.frames, HOT_FRAME)
    keep = np.ones(len(rec), bool)
    if min_target_c is not None:
        keep &= rec["max_target_temp_c"] >= min_target_c
    if max_grade is not None:
        keep &= rec["grade"] <= max_grade  # NaN (not graded) never passes, as in SQL
    for r in rec[keep]:
        grade = float(r["grade"])
        found = FoundFrame(row.session_id, int(r["idx"]), int(row.second) * 1_000_000_000 + int(r["offset_ns"]),
                           None if np.isnan(grade) else grade, int(r["target_count"]), float(r["max_target_temp_c"]))
        if after is None or found.rank() > (-after[0], after[1], after[2]):
            yield found


def search_targets(conn: Connection, *, limit: int, min_target_c: float | None = None,
                   max_grade: float | None = None, sensor: str | None = None,
                   after: tuple[float, str, int] | None = None, batch: int = 256) -> list[FoundFrame]:
    """Up to ``limit`` frames with a target, hottest first (then session, then frame), after the
    cursor ``after`` (its temperature, session and frame)."""
    t, s = db.target_seconds.c, db.sessions.c
    where: list[Any] = []
    if min_target_c is not None:
        where.append(t.max_target_temp_c >= min_target_c)
    if max_grade is not None:
        where.append(t.min_grade <= max_grade)
    if after is not None:
        where.append(t.min_target_temp_c <= after[0])  # a second wholly above the cursor was paged already
    q = select(t.session_id, t.second, t.max_target_temp_c, t.frames)
    if sensor:
        q = q.join(db.sessions, s.id == t.session_id)
        where.append(or_(s.sensor_id == sensor, s.sensor == sensor))
    q = q.where(and_(*where)) if where else q
    q = q.order_by(t.max_target_temp_c.desc(), t.session_id, t.second)
    found: list[FoundFrame] = []
    offset = 0
    while True:
        rows = conn.execute(q.limit(batch).offset(offset)).all()
        for k, row in enumerate(rows):
            found.extend(_frames_of(row, min_target_c, max_grade, after))
            if len(found) >= limit:
                found.sort(key=FoundFrame.rank)
                del found[limit:]
                # the rows below this one hold no target hotter than the next row's
                bound = rows[k + 1].max_target_temp_c if k + 1 < len(rows) else None
                if bound is not None and found[-1].max_target_temp_c > bound:
                    return found
        if len(rows) < batch:
            found.sort(key=FoundFrame.rank)
            return found[:limit]
        offset += batch
        batch = min(batch * 2, 4096)
