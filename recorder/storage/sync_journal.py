"""Every upload's state, on the vehicle's disk, so a dropped link or a reboot costs at most the
part that was in flight.

An object is *pending* until it is first sent, *in flight* while its multipart upload runs (the
upload id, part size and each confirmed part's number, size, ETag and sha256 are kept),
*uploaded* once the store assembled it, and *confirmed* once the cloud's receipt for exactly these
bytes came back.

A vehicle ships thousands of objects an hour, so journaling one part must not cost a rewrite of
every object ever shipped. The journal is a snapshot plus a log, in ``ROOT/.sync/``:

- ``journal.json`` holds the objects still live at the last compaction and its *generation*;
- ``journal-<generation>.log`` gets one fsynced JSON line per change since (the object's whole
  state, or its removal), so a change costs the size of one object;
- ``done.jsonl`` keeps, appended once, the objects sent and gone from the vehicle (evicted or
  freed after the store had them): nothing is left to resend or free, so they leave memory and
  the snapshot, not the record, and a recording of a week costs sync no more memory than an hour.

Compaction writes the next generation's snapshot atomically (temporary file, fsync, rename) and
only then deletes the old log, so a crash at any point leaves one consistent state. A torn last
line (the power went mid-append) costs that one change; damage anywhere else is named, not
guessed past.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["Journal", "ObjectState", "PartState"]

_SNAPSHOT = "journal.json"
_DONE = "done.jsonl"
_MIN_LOG_LINES = 512  # below this a compaction costs more than replaying the log does


@dataclass
class PartState:
    number: int
    size: int
    etag: str
    sha256: str


@dataclass
class ObjectState:
    key: str
    size: int
    sha256: str  # of the whole local file when the upload began
    mtime_ns: int
    state: str = "pending"  # pending | in_flight | uploaded | confirmed
    upload_id: str | None = None
    part_size: int = 0
    parts: list[PartState] = field(default_factory=list)
    attempts: int = 0  # parts sent, counting the ones that had to be sent again
    error: str | None = None
    # the sha256 a receipt named for bytes the cloud held before this copy was sent again: that
    # receipt is about the replaced bytes, so it neither confirms nor re-sends this copy
    stale_receipt: str | None = None

    @property
    def bytes_done(self) -> int:
        return self.size if self.state in ("uploaded", "confirmed") else sum(p.size for p in self.parts)

    @classmethod
    def from_json(cls, o: dict[str, Any]) -> ObjectState:
        o = dict(o)
        parts = [PartState(**p) for p in o.pop("parts", [])]
        return cls(**o, parts=parts)


class Journal:
    """The journal of one data root. ``read_only`` opens it for a reader beside a running sync
    (the ring asking what the cloud confirmed): it replays, and writes, cuts or deletes nothing."""

    def __init__(self, root: Path, *, read_only: bool = False) -> None:
        self.root = root
        self.dir = DataRoot.of(root).sync_dir
        self.path = self.dir / _SNAPSHOT
        self.read_only = read_only
        self.objects: dict[str, ObjectState] = {}
        self.generation = 0
        self._log_lines = 0
        self._lock = threading.Lock()
        self._log: Any = None
        self._load()

    @property
    def log_path(self) -> Path:
        return self.dir / f"journal-{self.generation}.log"

    # -- reading -------------------------------------------------------------------------------
    def _load(self) -> None:
        if self.path.is_file():
            try:
                raw = json.loads(self.path.read_text())
                self.generation = int(raw.get("generation", 0))
                for key, o in raw.get("objects", {}).items():
                    self.objects[key] = ObjectState.from_json(o)
            except (ValueError, TypeError) as exc:
                raise self._unreadable(self.path, exc) from None
        self._replay()

    def _replay(self) -> None:
        try:
            data = self.log_path.read_bytes()
        except FileNotFoundError:
            return
        lines = data.split(b"\n")
        good = len(data)
        for i, line in enumerate(lines):
            if not line:
                continue
            last = i == len(lines) - 1  # no newline after it: the append did not finish
            try:
                rec = json.loads(line)
                if "put" in rec:
                    self.objects[rec["put"]["key"]] = ObjectState.from_json(rec["put"])
                elif "forget" in rec:
                    self.objects.pop(rec["forget"], None)
                else:
                    raise ValueError(f"neither put nor forget: {sorted(rec)}")
            except (ValueError, TypeError, KeyError) as exc:
                if last:
                    good = len(data) - len(line)
                    break
                raise self._unreadable(self.log_path, exc) from None
            self._log_lines += 1
        if good < len(data) and not self.read_only:
            with open(self.log_path, "r+b") as f:  # cut the torn line so the next append starts clean
                f.truncate(good)
                os.fsync(f.fileno())

    def _unreadable(self, path: Path, exc: Exception) -> ThermcapError:
        return ThermcapError(f"{path}: the sync journal is unreadable ({exc}); move {self.dir} aside to start "
                             f"over (objects already in the store are found again, not sent twice)")

    def get(self, key: str) -> ObjectState | None:
        return self.objects.get(key)

    def finished(self) -> Iterator[tuple[str, str]]:
        """(key, state) of the objects sent and gone from the vehicle since the journal began
        (a key may repeat if a compaction was cut short)."""
        with contextlib.suppress(FileNotFoundError), open(self.dir / _DONE, "rb") as f:
            for line in f:
                with contextlib.suppress(ValueError, KeyError, TypeError):
                    rec = json.loads(line)
                    yield rec["key"], rec["state"]

    # -- writing -------------------------------------------------------------------------------
    def put(self, obj: ObjectState) -> None:
        """Journal ``obj``'s whole state now (durable when this returns)."""
        with self._lock:
            self.objects[obj.key] = obj
            self._append({"put": asdict(obj)})

    def forget(self, key: str) -> None:
        """Drop ``key`` (a segment evicted before it was sent: nothing of it is left to resume)."""
        with self._lock:
            if self.objects.pop(key, None) is not None:
                self._append({"forget": key})

    def _append(self, rec: dict[str, Any]) -> None:
        if self.read_only:
            raise ThermcapError(f"{self.dir}: this journal was opened to read")
        if self._log is None:
            self.dir.mkdir(parents=True, exist_ok=True)
            self._log = open(self.log_path, "ab")  # noqa: SIM115 (held open across appends; closed at compaction)
        self._log.write(json.dumps(rec, separators=(",", ":")).encode() + b"\n")
        self._log.flush()
        os.fsync(self._log.fileno())
        self._log_lines += 1
        if self._log_lines > max(_MIN_LOG_LINES, 2 * len(self.objects)):
            self._compact()

    def compact(self) -> None:
        """Fold the log into the next snapshot and move objects sent and gone from the vehicle
        to ``done.jsonl``. Whether a file is gone is looked at now, not remembered."""
        with self._lock:
            self._compact()

    def _compact(self) -> None:
        if self.read_only:
            raise ThermcapError(f"{self.dir}: this journal was opened to read")
        self.dir.mkdir(parents=True, exist_ok=True)
        gone = [st for st in self.objects.values()
                if st.state in ("uploaded", "confirmed") and not (self.root / st.key).exists()]
        if gone:
            with open(self.dir / _DONE, "ab") as f:
                for st in gone:
                    f.write(json.dumps({"key": st.key, "size": st.size, "sha256": st.sha256, "state": st.state},
                                       separators=(",", ":")).encode() + b"\n")
                f.flush()
                os.fsync(f.fileno())
            for st in gone:
                del self.objects[st.key]
        old_log = self.log_path
        if self._log is not None:
            self._log.close()
            self._log = None
        tmp = self.path.with_suffix(".tmp")
        data = {"version": 2, "generation": self.generation + 1,
                "objects": {k: asdict(v) for k, v in self.objects.items()}}
        with open(tmp, "w") as f:
            json.dump(data, f, separators=(",", ":"))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        self.generation += 1
        self._log_lines = 0
        with contextlib.suppress(FileNotFoundError):
            old_log.unlink()
        fd = os.open(self.dir, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    def close(self) -> None:
        with self._lock:
            if self._log is not None:
                self._log.close()
                self._log = None
