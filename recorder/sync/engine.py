"""The sync loop: ship what ``plan`` lists to a ``Target`` under the cap, journal every part,
and take the cloud's receipts back.

A part that fails (the link dropped, a timeout, the store refused its MD5) is sent again after a
backoff (0.5 s doubling to 30 s); what the store already holds is never sent again, even after a
reboot, because the journal keeps the upload id and the parts, and the store is asked which of
them it holds before going on. After ``max_failures`` failures in a row the pass stops: the link
is down, and the next pass (``--watch``) starts where this one stopped.

A segment counts as safe only once the cloud re-read it and its receipt names the same size and
sha256 the vehicle hashed: ``delete_confirmed`` frees only those (and never a segment inside a
protected event window).
"""

from __future__ import annotations

import base64
import hashlib
import io
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.digest import file_sha256
from thermcap.recorder.storage.layout import session_of_key
from thermcap.recorder.storage.ledger import record_freed
from thermcap.recorder.storage.ring import load_windows
from thermcap.recorder.storage.sync_journal import Journal, ObjectState, PartState
from thermcap.recorder.sync.plan import SyncItem, plan_root
from thermcap.recorder.sync.rate import RateLimit
from thermcap.recorder.sync.targets import Target, receipt_key

__all__ = ["SyncReport", "SyncStatus", "Syncer"]

log = logging.getLogger("thermcap.sync")
MIN_PART = 5 << 20  # S3's smallest part but the last


@dataclass
class SyncReport:
    sent_bytes: int = 0
    objects_done: int = 0
    parts_sent: int = 0
    parts_resent: int = 0
    confirmed: int = 0
    failed: list[str] = field(default_factory=list)
    stopped_early: bool = False
    # segments whose local bytes changed after the cloud confirmed them: the confirmed copy is
    # the good one (a closed segment never changes), so it is never overwritten from here
    diverged: list[str] = field(default_factory=list)
    # segments the vehicle's ring evicted before they were all sent: skipped, their partial gone
    evicted: list[str] = field(default_factory=list)


@dataclass
class SyncStatus:
    pending: list[str]
    in_flight: list[str]
    uploaded: list[str]  # in the store, waiting for the cloud's receipt
    confirmed: list[str]
    pending_bytes: int
    in_flight_bytes_done: int
    in_flight_bytes: int

    def to_dict(self) -> dict[str, Any]:
        return {"pending": len(self.pending), "in_flight": len(self.in_flight), "uploaded": len(self.uploaded),
                "confirmed": len(self.confirmed), "pending_bytes": self.pending_bytes,
                "in_flight_bytes_done": self.in_flight_bytes_done, "in_flight_bytes": self.in_flight_bytes,
                "objects": {"pending": self.pending, "in_flight": self.in_flight, "uploaded": self.uploaded,
                            "confirmed": self.confirmed}}


class _Throttled(io.RawIOBase):
    """A part's bytes, read out no faster than the cap allows (the HTTP client reads the body
    in blocks as it sends, so the cap holds on the wire, not only on average)."""

    def __init__(self, data: bytes, rate: RateLimit, on_bytes: Callable[[int], None]) -> None:
        self._buf = memoryview(data)
        self._pos = 0
        self._rate, self._on = rate, on_bytes

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        self._pos = {0: offset, 1: self._pos + offset, 2: len(self._buf) + offset}[whence]
        return self._pos

    def tell(self) -> int:
        return self._pos

    def read(self, n: int = -1) -> bytes:
        if n is None or n < 0:
            n = len(self._buf) - self._pos
        n = min(n, 1 << 16, len(self._buf) - self._pos)
        if n <= 0:
            return b""
        self._rate.take(n)
        out = bytes(self._buf[self._pos:self._pos + n])
        self._pos += n
        self._on(n)
        return out

    def readinto(self, b: Any) -> int:
        data = self.read(len(b))
        b[:len(data)] = data
        return len(data)


class Syncer:
    def __init__(self, root: Path, target: Target, *, rate: RateLimit | None = None, part_size: int = 8 << 20,
                 max_failures: int = 8, backoff_s: float = 0.5, max_backoff_s: float = 30.0,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if part_size < MIN_PART:
            raise ThermcapError(f"--part-size must be at least {MIN_PART >> 20} MiB (S3's smallest part)")
        self.root, self.target = root, target
        self.rate = rate or RateLimit()
        self.part_size = part_size
        self.max_failures, self.backoff_s, self.max_backoff_s = max_failures, backoff_s, max_backoff_s
        self.journal = Journal(root)
        self._sleep = sleep

    # -- shipping ------------------------------------------------------------------------------
    def run_once(self, sessions: list[str] | None = None,
                 on_progress: Callable[[str, int, int], None] | None = None) -> SyncReport:
        report = SyncReport()
        self._failures_in_a_row = 0
        for item in plan_root(self.root, sessions):
            try:
                if self._ship(item, report, on_progress):
                    report.objects_done += 1
            except _LinkDown as exc:
                report.failed.append(f"{item.key}: {exc}")
                report.stopped_early = True
                break
            except FileNotFoundError:
                if item.path.exists():
                    raise
                self._evicted(item, report)
        report.confirmed = self.check_receipts()
        return report

    def _evicted(self, item: SyncItem, report: SyncReport) -> None:
        """A segment gone from the vehicle before it was all sent: on a ring, the recorder evicts
        the oldest segments to keep its disk budget, whether or not sync holds them
        (``--evict-only-synced`` is the other policy). What was sent of it goes from the target,
        the journal forgets it, and the pass goes on; the report and the log name it."""
        st = self.journal.get(item.key)
        if st is not None and st.upload_id is not None:
            self.target.abort(item.key, st.upload_id)
        self.journal.forget(item.key)
        report.evicted.append(item.key)
        log.warning("sync: %s was evicted on the vehicle before it was sent; skipped", item.key)

    def _ship(self, item: SyncItem, report: SyncReport, on_progress: Callable[[str, int, int], None] | None) -> bool:
        st = self.journal.get(item.key)
        if st is not None and st.state in ("uploaded", "confirmed") and (st.size, st.mtime_ns) == (item.size,
                                                                                                  item.mtime_ns):
            return False
        if not item.segment:
            data = item.path.read_bytes()
            sha = hashlib.sha256(data).hexdigest()
            if st is not None and st.sha256 == sha and st.state in ("uploaded", "confirmed"):
                return False
            self._retry(item.key, lambda: self.target.put_small(item.key, data, sha), report)
            report.sent_bytes += len(data)
            self.journal.put(ObjectState(item.key, len(data), sha, item.mtime_ns, state="uploaded"))
            return True
        if st is not None and st.state == "confirmed" and (st.size, st.mtime_ns) != (item.size, item.mtime_ns):
            sha = file_sha256(item.path)
            if sha == st.sha256:  # touched, not changed
                st.mtime_ns = item.mtime_ns
                self.journal.put(st)
                return False
            log.warning("sync: %s changed on the vehicle after the cloud confirmed it; the confirmed copy is "
                        "kept and not overwritten (the local file may be damaged: `thermcap info` it)", item.key)
            report.diverged.append(item.key)
            return False
        if st is None or (st.size, st.mtime_ns) != (item.size, item.mtime_ns):
            sha = file_sha256(item.path)
            st = ObjectState(item.key, item.size, sha, item.mtime_ns, stale_receipt=st.stale_receipt if st else None)
            if self.target.complete_copy(item.key, item.size, sha):  # sent before the journal knew (a lost journal)
                st.state = "uploaded"
                self.journal.put(st)
                return True
        if st.upload_id is not None:
            held = self.target.parts_held(item.key, st.upload_id, [(p.number, p.size, p.etag) for p in st.parts])
            if held is None and self.target.complete_copy(item.key, item.size, st.sha256):
                st.state, st.upload_id = "uploaded", None  # completed just before a crash: the journal missed it
                self.journal.put(st)
                return True
            if held is None:  # the store forgot the upload (expired, aborted): start it again
                st.upload_id, st.parts = None, []
            else:
                st.parts = [p for p in st.parts if p.number in held]
        if st.upload_id is None:
            st.upload_id = self._retry(item.key, lambda: self.target.begin(item.key, item.size, st.sha256), report)
            st.part_size, st.parts = self.part_size, []
        st.state = "in_flight"
        self.journal.put(st)
        done = {p.number for p in st.parts}
        count = max(1, -(-item.size // st.part_size))
        with open(item.path, "rb") as f:
            for number in range(1, count + 1):
                if number in done:
                    continue
                offset = (number - 1) * st.part_size
                f.seek(offset)
                data = f.read(min(st.part_size, item.size - offset))
                md5 = base64.b64encode(hashlib.md5(data).digest()).decode()
                tries = [0]

                def send(number: int = number, offset: int = offset, data: bytes = data, md5: str = md5,
                         tries: list[int] = tries) -> str:
                    tries[0] += 1
                    body = _Throttled(data, self.rate, lambda n: None)
                    assert st.upload_id is not None
                    return self.target.put_part(item.key, st.upload_id, number, offset, body, len(data), md5)

                etag = self._retry(f"{item.key} part {number}", send, report)
                report.parts_sent += tries[0]
                report.parts_resent += tries[0] - 1
                report.sent_bytes += len(data) * tries[0]
                st.attempts += tries[0]
                st.parts.append(PartState(number, len(data), etag, hashlib.sha256(data).hexdigest()))
                self.journal.put(st)
                if on_progress:
                    on_progress(item.key, st.bytes_done, item.size)
        if file_sha256(item.path) != st.sha256:  # a closed segment never changes; if this one did, say so
            raise ThermcapError(f"{item.path}: changed while it was being sent; it is sent again on the next pass")
        parts = [(p.number, p.etag) for p in sorted(st.parts, key=lambda p: p.number)]
        upload_id = st.upload_id
        self._retry(item.key, lambda: self.target.complete(item.key, upload_id, parts, st.sha256), report)
        st.state, st.upload_id, st.error = "uploaded", None, None
        self.journal.put(st)
        return True

    def _retry(self, what: str, fn: Callable[[], Any], report: SyncReport) -> Any:
        delay = self.backoff_s
        while True:
            try:
                out = fn()
                self._failures_in_a_row = 0
                return out
            except ThermcapError:
                raise
            except Exception as exc:  # the link, the store: anything a retry may cure
                self._failures_in_a_row += 1
                log.warning("sync: %s failed (%s: %s); again in %.1f s", what, type(exc).__name__,
                            str(exc)[:200], delay)
                if self._failures_in_a_row >= self.max_failures:
                    raise _LinkDown(f"{self._failures_in_a_row} failures in a row, the last: "
                                    f"{type(exc).__name__}: {str(exc)[:200]}") from exc
                self._sleep(delay)
                delay = min(delay * 2, self.max_backoff_s)

    # -- receipts, status, freeing space ---------------------------------------------------------
    def check_receipts(self) -> int:
        """Take the cloud's receipts: a segment whose receipt names its exact size and sha256 is
        confirmed; one whose receipt says the cloud holds other bytes is sent again."""
        n = 0
        for st in list(self.journal.objects.values()):
            if st.state != "uploaded" or not st.key.endswith(".mcap"):
                continue
            try:
                r = self.target.get_json(receipt_key(st.key))
            except Exception as exc:  # the link: try again on the next pass
                log.warning("sync: no receipt for %s yet (%s)", st.key, exc)
                continue
            if r is None:
                continue
            if r.get("ok") and r.get("sha256") == st.sha256 and r.get("bytes") == st.size:
                st.state = "confirmed"
                self.journal.put(st)
                n += 1
            elif r.get("sha256") and r.get("sha256") != st.sha256:
                if r["sha256"] == st.stale_receipt:
                    continue  # about the bytes this copy replaced: wait for the cloud to check the new ones
                st.state, st.error = "pending", f"the cloud's copy differs (receipt: {r.get('problem') or r['sha256']})"
                st.stale_receipt = r["sha256"]
                st.mtime_ns = -1  # sent again on the next pass
                self.journal.put(st)
        return n

    def status(self, sessions: list[str] | None = None) -> SyncStatus:
        pending, flight, up, conf = [], [], [], []
        pending_bytes = flight_done = flight_bytes = 0
        for item in plan_root(self.root, sessions):
            st = self.journal.get(item.key)
            state = "pending" if st is None or (st.size, st.mtime_ns) != (item.size, item.mtime_ns) else st.state
            if state == "pending":
                pending.append(item.key)
                pending_bytes += item.size
            elif state == "in_flight":
                assert st is not None
                flight.append(item.key)
                flight_done += st.bytes_done
                flight_bytes += item.size
            elif state == "uploaded":
                up.append(item.key)
            else:
                conf.append(item.key)
        for st in self.journal.objects.values():  # confirmed and freed on the vehicle
            if sessions is not None and session_of_key(st.key) not in sessions:
                continue
            if st.state == "confirmed" and st.key not in conf and not (self.root / st.key).exists():
                conf.append(st.key)
        seen = set(conf) | set(up)
        for key, state in self.journal.finished():  # sent and gone long ago: out of memory, on record
            if key.endswith(".mcap") and key not in seen and (sessions is None or session_of_key(key) in sessions):
                seen.add(key)
                (conf if state == "confirmed" else up).append(key)
        return SyncStatus(pending, flight, up, conf, pending_bytes, flight_done, flight_bytes)

    def delete_confirmed(self) -> list[str]:
        """Delete local segments the cloud confirmed, byte for byte, outside protected windows."""
        freed = []
        for st in list(self.journal.objects.values()):
            if st.state != "confirmed" or not st.key.endswith(".mcap"):
                continue
            try:
                if self._free(st):
                    freed.append(st.key)
            except FileNotFoundError:
                continue  # the ring evicted it meanwhile (on record in eviction.log): nothing left to free
        return freed

    def _free(self, st: ObjectState) -> bool:
        from thermcap.recorder.storage.reader import segment_span

        path = self.root / st.key
        if not path.is_file():
            return False
        if path.stat().st_size != st.size or file_sha256(path) != st.sha256:
            return False  # changed since: not the bytes the cloud confirmed, and not freed on their word
        if not self._receipt_still_good(st.key, st.sha256, st.size):
            st.state, st.error = "pending", "the cloud's receipt no longer names these bytes; sent again"
            st.mtime_ns = -1
            self.journal.put(st)
            return False
        windows = load_windows(path.parent)
        if windows:
            start, end, _ = segment_span(path)
            if any(w.overlaps(start, end) for w in windows):
                return False
        path.unlink()
        record_freed(self.root, path.parent.name, path.name, st.size, "sync",
                     "the cloud confirmed its bytes (sha256 and size in its receipt)")
        return True

    def _receipt_still_good(self, key: str, sha256: str, size: int) -> bool:
        """The receipt read again at the moment of deleting: the last local copy goes only on
        what the cloud says now (a scrub there may have found the copy damaged since)."""
        try:
            r = self.target.get_json(receipt_key(key))
        except Exception as exc:  # the link is down: nothing is freed on old evidence
            log.warning("sync: %s kept, its receipt cannot be read now (%s)", key, exc)
            return False
        return bool(r and r.get("ok") and r.get("sha256") == sha256 and r.get("bytes") == size)


class _LinkDown(Exception):
    pass
