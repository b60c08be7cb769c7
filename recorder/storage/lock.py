"""The session lock: one process at a time changes a session folder's files.

Every writer of a session folder (the recorder for the whole recording, ``recover``, the
archiver, ``analyze``, gc, scrub) holds an exclusive ``flock`` on ``<session>/.lock`` while it
works; the OS releases it when the process dies, so a crash never leaves a stale lock. The lock
file names its holder (role and pid), so a refusal can say who is working on the session.

Readers never take it. ``holder()`` asks whether anyone holds it, which is how a reader tells a
live recording (``status: recording`` and a held lock) from one whose recorder died
(``interrupted``).
"""

from __future__ import annotations

import fcntl
import json
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path

from thermcap.recorder.exceptions import SessionBusyError, StorageError

__all__ = ["LOCK_NAME", "SessionLock", "holder", "is_locked", "lock_session", "session_locked", "session_status"]

LOCK_NAME = ".lock"


@dataclass
class SessionLock:
    """A held lock; ``release()`` (or leaving ``session_locked``) gives it back."""

    session_dir: Path
    fd: int
    role: str

    def release(self) -> None:
        if self.fd >= 0:
            with suppress(OSError):
                os.ftruncate(self.fd, 0)
            os.close(self.fd)
            self.fd = -1


def lock_session(session_dir: str | os.PathLike, role: str = "thermcap", *,
                 wait_s: float = 0.5) -> SessionLock | None:
    """Take the session's exclusive lock, or None if another process holds it.

    ``wait_s`` rides out a reader's momentary probe (``holder``); a real holder keeps it far
    longer. The holder's role and pid are written into the lock file for ``holder()``.
    """
    path = Path(session_dir) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise StorageError(f"{path}: cannot take the session lock ({exc.strerror or exc})") from None
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except BlockingIOError:
            if time.monotonic() >= deadline:
                os.close(fd)
                return None
            time.sleep(0.02)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"role": role, "pid": os.getpid()}).encode(), 0)
    except OSError:
        pass  # a read-only or full disk: the lock itself still holds
    return SessionLock(Path(session_dir), fd, role)


def holder(session_dir: str | os.PathLike) -> str | None:
    """Who holds the session's lock ("recorder (pid 1234)"), or None if nobody does.

    Probes with a shared lock, released at once, and never creates the lock file."""
    path = Path(session_dir) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                info = json.loads(os.pread(fd, 4096, 0) or b"{}")
                return f"{info.get('role', 'a process')} (pid {info.get('pid', '?')})"
            except (OSError, ValueError):
                return "another process"
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def is_locked(session_dir: str | os.PathLike) -> bool:
    return holder(session_dir) is not None


@contextmanager
def session_locked(session_dir: str | os.PathLike, role: str, *, wait_s: float = 0.5) -> Iterator[SessionLock]:
    """Hold the lock for a block; raises SessionBusyError naming the holder if it is taken."""
    lock = lock_session(session_dir, role, wait_s=wait_s)
    if lock is None:
        who = holder(session_dir) or "another process"
        raise SessionBusyError(f"{session_dir}: {who} is working on this session; try again when it is done")
    try:
        yield lock
    finally:
        lock.release()


def session_status(session_dir: str | os.PathLike, recorded: str | None) -> tuple[str, str]:
    """The status to show for a session and a hint: ``recording`` only while a live process
    holds the lock; a session.json that still says so with nobody holding it was interrupted
    (the recorder died), and ``recover`` turns its open segment into a finished one."""
    d = Path(session_dir)
    status = recorded or "unknown"
    if status == "recording" and holder(d) is None:
        return "interrupted", f"the recorder stopped without finishing; run `thermcap recover {d}`"
    if status in ("complete", "recovered", "failed") and any(d.glob("*.mcap.active")) and holder(d) is None:
        return status, f"unfinished segments remain; run `thermcap recover {d}`"
    return status, ""
