"""Always-on recording within a disk budget: the oldest unprotected segments of ring sessions are
deleted, off the capture and writer threads, and every deletion is logged with its reason.

A segment is protected when its time span overlaps an event window (``protected.json`` of its
session: a trigger's ``pre`` seconds before to ``post`` seconds after). Only finished segments
of sessions recorded with ``--ring`` are ever candidates, and never the open one. The recorder's
writer thread evicts right after it closes a segment and before it opens the next (an unlink,
never on the capture thread), so the root stays within the budget plus the open segment however
fast frames come; this thread also watches for space taken by anything else. When nothing
can be deleted and the budget is still exceeded, the evictor says so (``blocked``) and the
recorder drops and counts frames rather than fill the disk.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.icd.names import iso_utc
from thermcap.recorder.sizes import parse_size
from thermcap.recorder.storage.atomic import fsync_dir, write_json_atomic
from thermcap.recorder.storage.layout import ACTIVE_SUFFIX, RESERVE_FILE, DataRoot, SessionLayout
from thermcap.recorder.storage.lock import holder
from thermcap.recorder.storage.reader import segment_span
from thermcap.recorder.storage.rosbag2 import write_bag_metadata

__all__ = ["Eviction", "Evictor", "ProtectionBook", "RingPolicy", "Window", "disk_usage", "parse_size"]


#: The smallest --max-disk a ring takes.
MIN_RING_BYTES = 1 << 20


@dataclass(frozen=True)
class FittedDefaults:
    """Segment length and event window derived from a disk budget (``fit_to_budget``)."""

    segment_s: float
    pre_s: float
    post_s: float


def fit_to_budget(max_disk: int, protected: int, raw_bytes_per_s: float, segment_s: float = 60.0,
                  window_s: float = 30.0) -> FittedDefaults:
    """The defaults (60 s segments, 30 s either side of an event) shrunk to what a small budget
    holds, at the raw rate (compression only makes it hold more): a segment at most a tenth of
    ``max_disk``, so the ring has segments to choose from; a window such that two of them, each
    counted by the whole segments it touches (up to one more than it spans), fit in ``protected``.
    A vehicle's real budget (hundreds of GB) leaves the defaults as they are; the page's 200M at
    640x512 and 60 fps gets 0.5 s segments and windows the share of the budget can keep."""
    rate = max(raw_bytes_per_s, 1.0)
    seg = min(segment_s, max(0.25, max_disk / rate / 10))
    seg = round(seg, 2)
    span = protected / 2 / rate - seg  # two windows, each up to one segment more than it spans
    half = max(0.0, min(window_s, span / 2))
    return FittedDefaults(seg, round(half, 2), round(half, 2))


@dataclass(frozen=True)
class RingPolicy:
    max_disk: int | None = None  # bytes the data root may hold
    min_free: int | None = None  # bytes that must stay free on its filesystem
    min_free_percent: float | None = None  # or this share of the filesystem
    pre_s: float = 30.0  # kept before a trigger
    post_s: float = 30.0  # kept after it
    interval_s: float = 1.0  # how often the evictor looks, besides after every segment
    require_receipt: bool = False  # evict only segments the cloud confirmed (``thermcap sync``'s receipts)
    max_protected: int | None = None  # bytes event windows may hold (default: half of max_disk)
    keep_events: bool = False  # the operator prefers old events to new frames: windows never expire

    @property
    def protected_budget(self) -> int | None:
        """The share of the budget event windows may hold before the oldest one goes."""
        if self.max_protected is not None:
            return self.max_protected
        return self.max_disk // 2 if self.max_disk is not None else None

    @classmethod
    def parse(cls, max_disk: str | None, min_free: str | None, pre_s: float, post_s: float,
              require_receipt: bool = False, max_protected: str | None = None,
              keep_events: bool = False) -> RingPolicy:
        pct = None
        free = None
        if min_free:
            if min_free.strip().endswith("%"):
                try:
                    pct = float(min_free.strip()[:-1])
                except ValueError:
                    raise ValueError(f"--min-free {min_free!r} is not a share like 10%") from None
                if not 0 < pct < 100:
                    raise ValueError(f"--min-free {min_free}: a share of the disk is between 0% and 100%")
            else:
                free = parse_size(min_free)
        disk = parse_size(max_disk) if max_disk else None
        if disk is not None and disk < MIN_RING_BYTES:
            raise ValueError(f"--max-disk {max_disk}: a ring needs room for the segment being written and the ones "
                             f"kept before it; at least {MIN_RING_BYTES >> 20}M")
        protected = parse_size(max_protected) if max_protected else None
        if protected is not None and disk is not None and protected > disk:
            raise ValueError(f"--max-protected {max_protected} is more than --max-disk {max_disk}")
        if protected is not None and keep_events:
            raise ValueError("--max-protected and --keep-events contradict each other: the one caps event windows, "
                             "the other keeps them all")
        return cls(disk, free, pct, pre_s, post_s, require_receipt=require_receipt, max_protected=protected,
                   keep_events=keep_events)


@dataclass(frozen=True)
class Window:
    start_ns: int
    end_ns: int
    reason: str  # "manual", "signal", "hot_spot", "target_count", "crossover", "radar_cue"
    note: str = ""

    def overlaps(self, start_ns: int, end_ns: int) -> bool:
        return self.start_ns <= end_ns and start_ns <= self.end_ns


class ProtectionBook:
    """A session's event windows: in memory for the evictor of this process (under one lock, so a
    window added while a deletion is being decided is honoured), and in ``protected.json`` for
    gc, the archiver and the next process."""

    def __init__(self, session_dir: Path) -> None:
        self.path = SessionLayout.of(session_dir).protected_json
        self.lock = threading.Lock()
        self.windows: list[Window] = load_windows(session_dir)

    def add(self, window: Window) -> None:
        with self.lock:
            self.windows.append(window)
            write_json_atomic(self.path, {"windows": [asdict(w) for w in self.windows]})

    def protects(self, start_ns: int, end_ns: int) -> bool:
        return any(w.overlaps(start_ns, end_ns) for w in self.windows)

    def expire(self, window: Window, why: str) -> None:
        """The window stops protecting its segments; protected.json keeps it under ``expired``
        with why, so nobody reads its loss as silence."""
        with self.lock:
            self.windows.remove(window)
            try:
                expired = json.loads(self.path.read_text()).get("expired", [])
            except (OSError, ValueError, AttributeError):
                expired = []
            expired.append({**asdict(window), "expired_at": iso_utc(time.time_ns()), "why": why})
            write_json_atomic(self.path, {"windows": [asdict(w) for w in self.windows], "expired": expired})


def load_windows(session_dir: Path) -> list[Window]:
    path = SessionLayout.of(session_dir).protected_json
    try:
        return [Window(**w) for w in json.loads(path.read_text()).get("windows", [])]
    except FileNotFoundError:
        return []
    except (ValueError, TypeError) as exc:  # unreadable: protect everything rather than guess
        return [Window(0, 2**63 - 1, f"unreadable {path.name}: {exc}")]


@dataclass
class Eviction:
    at: str
    session: str
    segment: str
    bytes: int
    frames: int
    start: str | None
    end: str | None
    reason: str


def disk_usage(root: Path) -> int:
    """Bytes the data root holds, as the ring counts them: a recording's end-of-run reserve is
    not data (it is freed before the summary is written)."""
    total = 0
    for dirpath, _dirs, names in os.walk(root):
        for n in names:
            if n == RESERVE_FILE:
                continue
            try:
                total += os.lstat(os.path.join(dirpath, n)).st_blocks * 512
            except OSError:
                continue  # deleted while we looked
    return total


@dataclass
class _Candidate:
    path: Path
    session_dir: Path
    start_ns: int
    end_ns: int
    frames: int


@dataclass
class EvictorState:
    evicted_bytes: int = 0
    evicted_segments: int = 0
    blocked: bool = False
    blocked_reason: str | None = None
    last: list[Eviction] = field(default_factory=list)
    windows_expired: int = 0  # event windows that went because the ring needed their share
    last_expired: str | None = None  # what the last expiry said
    last_expired_mono: float | None = None  # when (time.monotonic), for health's alert window


class Evictor(threading.Thread):
    """Keeps ROOT within the ring policy. ``books`` maps a ring session's folder to its
    ProtectionBook (the live one for the session this process records)."""

    def __init__(self, root: Path, policy: RingPolicy, books: dict[Path, ProtectionBook],
                 log: Callable[[str], None] = lambda m: None) -> None:
        super().__init__(name="thermcap-evictor", daemon=True)
        self.root, self.policy, self.books, self.log = Path(root), policy, books, log
        self.state = EvictorState()
        self._wake = threading.Event()
        self._halt = threading.Event()
        self._spans: dict[Path, tuple[int, int, int]] = {}
        self._busy = threading.Lock()  # the writer (after each segment) and this thread take turns

    def wake(self) -> None:
        self._wake.set()

    def stop(self) -> None:
        self._halt.set()
        self._wake.set()
        self.join()

    def run(self) -> None:
        while not self._halt.is_set():
            try:
                self.evict_once()
            except Exception as exc:  # never take the recording down; say why on stats and in the log
                self.state.blocked, self.state.blocked_reason = True, f"evictor failed: {type(exc).__name__}: {exc}"
            self._wake.wait(self.policy.interval_s)
            self._wake.clear()

    # -- decisions ---------------------------------------------------------------------------------
    def pressure(self, used: int | None = None) -> str | None:
        """Why space must be freed now, or None. ``used``: the data root's bytes, when the caller
        already knows them (one walk of the tree per eviction pass, not one per deletion)."""
        p = self.policy
        if p.max_disk is not None:
            used = disk_usage(self.root) if used is None else used
            if used > p.max_disk:
                return f"data root holds {used:,} bytes, over --max-disk {p.max_disk:,}"
        if p.min_free is not None or p.min_free_percent is not None:
            du = shutil.disk_usage(self.root)
            if p.min_free is not None and du.free < p.min_free:
                return f"{du.free:,} bytes free, under --min-free {p.min_free:,}"
            if p.min_free_percent is not None and du.free / du.total * 100 < p.min_free_percent:
                return f"{du.free / du.total * 100:.1f}% free, under --min-free {p.min_free_percent}%"
        return None

    def _candidates(self) -> list[_Candidate]:
        out = []
        for session_dir in self._ring_sessions():
            for seg in SessionLayout.of(session_dir).segments():
                if seg not in self._spans:
                    try:
                        self._spans[seg] = segment_span(seg)
                    except Exception:  # unreadable: never a candidate
                        continue
                start, end, frames = self._spans[seg]
                out.append(_Candidate(seg, session_dir, start, end, frames))
        return sorted(out, key=lambda c: (c.start_ns, str(c.path)))

    def _ring_sessions(self) -> list[Path]:
        found = set(self.books)
        for d in DataRoot.of(self.root).session_dirs():
            sj = SessionLayout.of(d).session_json
            try:
                if json.loads(sj.read_text()).get("ring"):
                    found.add(d)
            except (OSError, ValueError):
                continue
        return sorted(found)

    def _book(self, session_dir: Path) -> ProtectionBook:
        if session_dir not in self.books:
            self.books[session_dir] = ProtectionBook(session_dir)
        return self.books[session_dir]

    def evict_once(self) -> list[Eviction]:
        with self._busy:
            return self._evict()

    def _evict(self) -> list[Eviction]:
        """Oldest first, skipping protected segments, until nothing presses; the tree is walked
        and the candidates listed once per pass, and each deletion is subtracted. Each session
        touched gets its rosbag2 metadata.yaml rewritten once, at the end of the pass."""
        touched: set[Path] = set()
        try:
            return self._evict_pass(touched)
        finally:
            for d in touched:
                with contextlib.suppress(OSError):  # derived data: the next change writes it again
                    write_bag_metadata(d)

    def _evict_pass(self, touched: set[Path]) -> list[Eviction]:
        """Under pressure: event windows over their share (``protected_budget``) lose the oldest
        first; then the oldest unprotected segments go; when nothing unprotected is left, the
        oldest window goes too, unless ``keep_events`` (then the ring blocks, as the operator
        chose). Every expiry is logged, counted and shown on health."""
        done: list[Eviction] = []
        used = disk_usage(self.root) if self.policy.max_disk is not None else None
        if (reason := self.pressure(used)) is None:
            self.state.blocked, self.state.blocked_reason = False, None
            return done
        confirmed = self._confirmed() if self.policy.require_receipt else None
        while True:
            candidates = self._candidates()
            if not self.policy.keep_events:
                self._expire_over_share(candidates)
            for c in candidates:
                key = c.path.relative_to(self.root).as_posix()
                if confirmed is not None and confirmed.get(key) != c.path.stat().st_size:
                    continue  # not yet safe in the cloud: kept, whatever the pressure
                book = self._book(c.session_dir)
                with book.lock:  # a window added now is seen before the file goes
                    if book.protects(c.start_ns, c.end_ns):
                        continue
                    st = c.path.stat()
                    c.path.unlink()
                self._record_eviction(c, st.st_size, reason)
                touched.add(c.session_dir)
                done.append(self.state.last[-1])
                if used is not None:
                    used -= st.st_blocks * 512  # as disk_usage counts it
                if (reason := self.pressure(used)) is None:
                    self.state.blocked, self.state.blocked_reason = False, None
                    return done
            if self.policy.keep_events or not self._expire_oldest(
                    candidates, f"nothing else can go ({reason}); new frames come before old events"):
                break
        if self.policy.require_receipt:
            reason += "; the rest is protected or not yet confirmed by the cloud (thermcap sync)"
        if self.policy.keep_events:
            reason += "; --keep-events keeps every event window"
        if settling := self._settling():
            reason += f"; {settling} closed segments still wait for fsync and cannot go until they settle"
        if not self.state.blocked:
            self.log(f"ring: cannot free space, no finished segment can go ({reason})")
        self.state.blocked, self.state.blocked_reason = True, reason
        return done

    def protected_bytes(self) -> int:
        """Bytes of the segments event windows protect now."""
        return self._protected_bytes(self._candidates())

    def _protected_bytes(self, candidates: list[_Candidate]) -> int:
        total = 0
        for c in candidates:
            if self._book(c.session_dir).protects(c.start_ns, c.end_ns):
                with contextlib.suppress(OSError):
                    total += c.path.stat().st_blocks * 512
        return total

    def _expire_over_share(self, candidates: list[_Candidate]) -> None:
        budget = self.policy.protected_budget
        if budget is None:
            return
        while (held := self._protected_bytes(candidates)) > budget:
            if not self._expire_oldest(candidates, f"event windows hold {held:,} bytes, over --max-protected "
                                                   f"{budget:,}"):
                return

    def _expire_oldest(self, candidates: list[_Candidate], why: str) -> bool:
        """The oldest window that protects a finished segment stops protecting; False if none does."""
        found: list[tuple[Window, Path]] = []
        for d in {c.session_dir for c in candidates}:
            book = self._book(d)
            for w in book.windows:
                if any(c.session_dir == d and w.overlaps(c.start_ns, c.end_ns) for c in candidates):
                    found.append((w, d))
        if not found:
            return False
        window, d = min(found, key=lambda f: (f[0].start_ns, str(f[1])))
        self._book(d).expire(window, why)
        entry = {"at": iso_utc(time.time_ns()), "session": d.name, "expired_window": asdict(window),
                 "reason": why}
        with open(DataRoot.of(self.root).eviction_log, "a") as f:
            f.write(json.dumps(entry) + "\n")
        self.state.windows_expired += 1
        self.state.last_expired_mono = time.monotonic()
        self.state.last_expired = (f"{d.name}: the {window.reason} window {iso_utc(window.start_ns)}.."
                                   f"{iso_utc(window.end_ns)} ({window.note or 'no note'}) expired: {why}")
        self.log(f"ring: WARNING: {self.state.last_expired}")
        return True

    def _settling(self) -> int:
        """Closed segments of ring sessions being recorded, not yet renamed (a stalled fsync):
        each such session's ``.active`` files but the one it is writing. Not candidates, so they
        can hold the root over its budget, and the reason must say so. A session nobody holds
        has leftovers for ``recover``, not segments settling."""
        n = 0
        for d in self._ring_sessions():
            if holder(d) is None:
                continue
            with contextlib.suppress(OSError):
                n += max(0, sum(1 for _ in d.glob(f"*.mcap{ACTIVE_SUFFIX}")) - 1)
        return n

    def _confirmed(self) -> dict[str, int]:
        """Segments the cloud confirmed byte for byte: key -> size, from sync's journal."""
        from thermcap.recorder.storage.sync_journal import Journal

        try:
            journal = Journal(self.root, read_only=True)
        except Exception:  # an unreadable journal confirms nothing
            return {}
        return {k: o.size for k, o in journal.objects.items() if o.state == "confirmed"}

    def _record_eviction(self, victim: _Candidate, size: int, reason: str) -> None:
        self._spans.pop(victim.path, None)
        fsync_dir(victim.session_dir)
        ev = Eviction(at=iso_utc(time.time_ns()), session=victim.session_dir.name, segment=victim.path.name,
                      bytes=size, frames=victim.frames, start=iso_utc(victim.start_ns),
                      end=iso_utc(victim.end_ns), reason=reason)
        with open(DataRoot.of(self.root).eviction_log, "a") as f:
            f.write(json.dumps(asdict(ev)) + "\n")
        self.state.evicted_bytes += size
        self.state.evicted_segments += 1
        self.state.last = [*self.state.last[-9:], ev]
        self.log(f"ring: deleted {victim.session_dir.name}/{victim.path.name} ({size:,} bytes): {reason}")


def read_eviction_log(root: Path) -> list[dict[str, Any]]:
    path = DataRoot.of(root).eviction_log
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
