"""Every upload's state, on the vehicle's disk, so a dropped link or a reboot costs at most the
part that was in flight.

One JSON file per data root (``ROOT/.sync/journal.json``), rewritten atomically (temporary file,
fsync, rename) after every part. An object is *pending* until it is first sent, *in flight*
while its multipart upload runs (the upload id, part size and each confirmed part's number,
size, ETag and sha256 are kept), *uploaded* once the store assembled it, and *confirmed* once the
cloud's receipt for exactly these bytes came back.
"""

from __future__ import annotations

import json
import os
import threading
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError

__all__ = ["Journal", "ObjectState", "PartState"]

JOURNAL_DIR = ".sync"


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


class Journal:
    def __init__(self, root: Path) -> None:
        self.path = root / JOURNAL_DIR / "journal.json"
        self.objects: dict[str, ObjectState] = {}
        self._lock = threading.Lock()
        if self.path.is_file():
            try:
                raw = json.loads(self.path.read_text())
                for key, o in raw.get("objects", {}).items():
                    parts = [PartState(**p) for p in o.pop("parts", [])]
                    self.objects[key] = ObjectState(**o, parts=parts)
            except (ValueError, TypeError) as exc:
                raise ThermcapError(f"{self.path}: the sync journal is unreadable ({exc}); move it aside to start "
                                    f"over (objects already in the store are found again, not sent twice)") from None

    def get(self, key: str) -> ObjectState | None:
        return self.objects.get(key)

    def put(self, obj: ObjectState) -> None:
        with self._lock:
            self.objects[obj.key] = obj
            self._save()

    def forget(self, key: str) -> None:
        """Drop ``key`` (a segment evicted before it was sent: nothing of it is left to resume)."""
        if self.objects.pop(key, None) is not None:
            self.save()

    def save(self) -> None:
        with self._lock:
            self._save()

    def _save(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        data: dict[str, Any] = {"version": 1, "objects": {k: asdict(v) for k, v in self.objects.items()}}
        with open(tmp, "w") as f:
            json.dump(data, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
