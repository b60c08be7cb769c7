"""The detector in a child process, fed through a ring of shared-memory frame slots.

The recording process copies each frame into a free slot (a memcpy) and sends the slot's number
over a socket; the child runs the detector on the slot in place and sends back the small
result, which frees the slot. A child that is behind (more frames wait in its socket) sends its
results in batches of up to a quarter of the slots, so the recorder's results thread wakes once
for several frames; an idle child answers each frame at once. There are as many slots as the
analysis queue is long, so the child is never more than that many frames behind: a file source
waits for a free slot (every frame is analysed), a live source does not (the frame is counted as
skipped). A frame larger than a slot (a source that changes size) travels in the socket instead,
still holding a slot.

A frame of counts too flat to hold any candidate (a wall, fog, a lens cap) is answered here and
never travels (``HotSpotDetector.flat_answer``, exact); the next frame that travels tells the
child to forget its tracks first, as that frame would have made it. Handing a frame over cost a
file source of a flat 640x512 view more than the detector's answer (0.12-0.21 ms a frame in
this process, against the detector's 0.12-0.15 in the child).

The child is a fresh interpreter running this module (``python -m``), not a multiprocessing
child: those import the parent's ``__main__`` again, which re-runs a user's unguarded script
(seen: the forkserver ran the recording's own command line). The slots are an anonymous memfd
handed to the child, so nothing is left in /dev/shm whatever way either process ends. If the
child dies, every frame it held, and every later one, is answered ``None`` (skipped, counted)
and the reason is kept in :attr:`ProcessRunner.failure`; nothing waits on it forever.
"""

from __future__ import annotations

import argparse
import contextlib
import mmap
import os
import pickle
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import Future
from multiprocessing.connection import Connection

import numpy as np

from thermcap.recorder.analysis import detector_kernels
from thermcap.recorder.analysis.answers import analyse_one
from thermcap.recorder.analysis.child_env import child_env
from thermcap.recorder.analysis.detector import HotSpotDetector
from thermcap.recorder.frame_heap import FRAME_HEAP_ENV

__all__ = ["ProcessRunner", "RunnerUnavailable"]


_START_TIMEOUT_S = 60.0  # an interpreter and scipy on a loaded machine; seconds at most, usually 0.3


def _child_env() -> dict[str, str]:
    env = child_env()
    # the detector's frame-sized temporaries stay in the heap (see recorder.frame_heap)
    for key, value in FRAME_HEAP_ENV.items():
        env.setdefault(key, value)
    # one thread does the child's work: numpy's and scipy's OpenBLAS each started a pool of
    # workers that spun at import, 0.1-0.3 s of CPU before the first frame, for no BLAS call
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


class RunnerUnavailable(RuntimeError):
    """No child process could be started here; the recorder falls back to a thread."""


class ProcessRunner:
    kind = "process"

    def __init__(self, detector: HotSpotDetector, slots: int, frame_bytes: int,
                 name: str = "thermcap-analysis", batch: int | None = None) -> None:
        """``batch``: the most results the child sends in one message while it is behind
        (default a quarter of the slots; 1 answers every frame in a message of its own)."""
        slots = self.slots = max(1, slots)
        self.batch = max(1, slots // 4 if batch is None else batch)
        try:
            payload = pickle.dumps(detector)
        except Exception as exc:
            raise RunnerUnavailable(f"the detector cannot be sent to a child process ({exc})") from exc
        self.failure: str | None = None
        self._detector = detector  # this process's copy answers the flat frames (flat_answer)
        self._forget = False  # a frame answered here since the last one sent: the child's tracks go
        self.answered_here = 0
        #: the child's last word on its compiled passes: {"kernels": detector_kernels.state(),
        #: "frames_before_kernels": frames answered on numpy while they compiled}
        self.kernels: dict[str, object] = {}
        self._slot_bytes = max(int(frame_bytes), 16)
        size = self._slot_bytes * slots
        if not hasattr(os, "memfd_create"):
            raise RunnerUnavailable("no memfd on this system for the frame slots")
        memfd = -1
        ours = theirs = None
        try:
            memfd = os.memfd_create("thermcap-frames", os.MFD_CLOEXEC)
            os.ftruncate(memfd, size)
            self._mm = mmap.mmap(memfd, size)
            ours, theirs = socket.socketpair()
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "thermcap.recorder.analysis.process_runner", "--socket", str(theirs.fileno()),
                 "--memfd", str(memfd), "--size", str(size), "--slot-bytes", str(self._slot_bytes),
                 "--batch", str(self.batch)],
                pass_fds=(theirs.fileno(), memfd), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL, start_new_session=True, env=_child_env())
        except (OSError, ValueError, subprocess.SubprocessError) as exc:
            if ours is not None:
                ours.close()
            raise RunnerUnavailable(f"the detector process did not start ({type(exc).__name__}: {exc})") from exc
        finally:
            if theirs is not None:
                theirs.close()
            if memfd >= 0:
                os.close(memfd)  # the mapping and the child keep the memory
        self._conn = Connection(ours.detach())
        self._handshake(payload)
        self._views = [np.frombuffer(self._mm, np.uint8, self._slot_bytes, i * self._slot_bytes)
                       for i in range(slots)]
        self._free: queue.Queue[int] = queue.Queue()
        for i in range(slots):
            self._free.put(i)
        self._pending: dict[int, tuple[Future, int]] = {}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._seq = 0
        self._cpu = 0.0
        self._messages = 0
        self._closing = False
        self._reader = threading.Thread(target=self._read_loop, name=f"{name}-results", daemon=True)
        self._reader.start()

    @property
    def answer_messages(self) -> int:
        """How many messages of results the child has sent: fewer than the frames it answered
        when it was behind and batched them."""
        return self._messages

    def _handshake(self, payload: bytes) -> None:
        """Send the detector and wait until the child holds it: a child that cannot start (an
        interpreter without thermcap, a detector it cannot rebuild) means the thread instead,
        not a recording whose every frame is skipped."""
        why = None
        try:
            self._conn.send_bytes(payload)
            if not self._conn.poll(_START_TIMEOUT_S):
                why = f"no answer in {_START_TIMEOUT_S:g} s"
            else:
                msg = self._conn.recv()
                if msg[0] != "ready":
                    why = str(msg[1])
        except (OSError, EOFError) as exc:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._proc.wait(timeout=5.0)
            why = f"it ended at start (exit code {self._proc.returncode}; {type(exc).__name__})"
        if why is not None:
            with contextlib.suppress(OSError):
                self._proc.kill()
            with contextlib.suppress(OSError):
                self._conn.close()
            self._mm.close()
            raise RunnerUnavailable(f"the detector process did not start: {why}")

    # -- the recording side ------------------------------------------------------------------
    def submit(self, pixels: np.ndarray, fut: Future, *, wait: bool) -> bool:
        if self.failure is None:
            flat = self._detector.flat_answer(pixels)
            if flat is not None:  # no slot, no message: see the module's docstring
                self._forget = True
                self.answered_here += 1
                fut.set_result(flat)
                return True
        slot = self._take_slot(wait)
        if slot is None:
            return False
        arr = np.ascontiguousarray(pixels)
        inline = None
        if arr.nbytes <= self._slot_bytes:
            self._views[slot][:arr.nbytes].view(arr.dtype).reshape(arr.shape)[...] = arr
        else:
            inline = arr
        with self._lock:
            if self.failure is not None:
                self._free.put(slot)
                return False
            seq = self._seq
            self._seq += 1
            self._pending[seq] = (fut, slot)
            forget, self._forget = self._forget, False
        try:
            with self._send_lock:
                self._conn.send((seq, slot, arr.shape, arr.dtype.str, inline, forget))
        except (OSError, ValueError):  # the child is gone: the reader answers what it held
            with self._lock:
                self._pending.pop(seq, None)
            self._free.put(slot)
            return False
        return True

    def _take_slot(self, wait: bool) -> int | None:
        if not wait:
            try:
                return self._free.get_nowait()
            except queue.Empty:
                return None
        while self.failure is None:
            try:
                return self._free.get(timeout=0.5)
            except queue.Empty:
                continue
        return None

    def close(self, timeout_s: float) -> None:
        """Ask the child to finish what it holds and stop; past ``timeout_s`` it is terminated
        and whatever it still held is answered ``None``."""
        self._closing = True
        with contextlib.suppress(OSError, ValueError), self._send_lock:
            self._conn.send(None)
        self._reader.join(timeout=max(timeout_s, 0.1))
        if self._reader.is_alive():
            self._proc.terminate()
            self._reader.join(timeout=5.0)
        try:
            self._proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(timeout=5.0)
        with contextlib.suppress(OSError):
            self._conn.close()
        self._views = []
        with contextlib.suppress(BufferError, ValueError):
            self._mm.close()

    @property
    def cpu_s(self) -> float:
        return self._cpu

    @property
    def native_ids(self) -> dict[str, int]:
        return {}  # the detector runs in the child: its CPU is in cpu_s

    @property
    def pid(self) -> int | None:
        return self._proc.pid

    def _read_loop(self) -> None:
        reason: str | None = None
        while True:
            try:
                msg = self._conn.recv()
            except (EOFError, OSError):
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self._proc.wait(timeout=1.0)
                code = self._proc.returncode
                reason = f"the detector process ended unexpectedly (exit code {code})"
                break
            if msg[0] == "results":
                self._messages += 1
                for seq, result in msg[1]:
                    with self._lock:
                        fut, slot = self._pending.pop(seq)
                    self._free.put(slot)
                    fut.set_result(result)
            elif msg[0] == "done":
                self._cpu = float(msg[1])
                self.kernels = dict(msg[2])
                break
            else:  # "failed": the child could not set itself up
                reason = str(msg[1])
                break
        with self._lock:
            if reason is not None and not self._closing:
                self.failure = reason
            elif reason is not None:
                self.failure = self.failure or reason
            else:
                self.failure = self.failure or "closed"
            held, self._pending = list(self._pending.values()), {}
        for fut, slot in held:
            self._free.put(slot)
            fut.set_result(None)


def _child_main(conn: Connection, slots: mmap.mmap, slot_bytes: int, batch: int = 1) -> None:
    """The child: run the detector on each slot it is told of, in order, until told to stop.
    Results wait to be sent while more frames wait in the socket, up to ``batch`` of them."""
    try:
        detector = pickle.loads(conn.recv_bytes())
        detector_kernels.warm_in_background()  # numpy answers until the compiled passes run
        detector.prime()
    except Exception as exc:
        with contextlib.suppress(Exception):
            conn.send(("failed", f"the detector process could not start: {type(exc).__name__}: {exc}"))
        return
    conn.send(("ready",))
    cpu0 = time.process_time()
    held: list[tuple[int, object]] = []
    before_kernels = 0  # frames answered on the numpy path while the kernels were compiled beside it
    while True:
        if held and (len(held) >= batch or not conn.poll(0)):
            _send_results(conn, held)
            held = []
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return  # the recorder is gone
        if msg is None:
            break
        seq, slot, shape, dtype, inline, forget = msg
        if forget:  # frames answered in the recorder since the last one: none held a target
            detector.forget_tracks()
        before_kernels += detector_kernels.state() == "warming"
        if inline is not None:
            result = analyse_one(detector, inline)
        else:
            count = int(np.prod(shape))
            pixels = np.frombuffer(slots, np.dtype(dtype), count, slot * slot_bytes).reshape(shape)
            result = analyse_one(detector, pixels)
            del pixels  # no view may outlive the slot: the recorder reuses it
        held.append((seq, result))
    if held:
        _send_results(conn, held)
    conn.send(("done", time.process_time() - cpu0, {"kernels": detector_kernels.state(),
                                                     "frames_before_kernels": before_kernels}))


def _send_results(conn: Connection, held: list[tuple[int, object]]) -> None:
    try:
        conn.send(("results", held))
    except (pickle.PicklingError, TypeError, AttributeError):  # one result that cannot travel: None for it alone
        for seq, result in held:
            try:
                conn.send(("results", [(seq, result)]))
            except (pickle.PicklingError, TypeError, AttributeError):
                conn.send(("results", [(seq, None)]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="thermcap-detector", description="the recorder's detector process")
    parser.add_argument("--socket", type=int, required=True)
    parser.add_argument("--memfd", type=int, required=True)
    parser.add_argument("--size", type=int, required=True)
    parser.add_argument("--slot-bytes", type=int, required=True)
    parser.add_argument("--batch", type=int, default=1)
    args = parser.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the recorder, which stops us
    conn = Connection(args.socket)
    slots = mmap.mmap(args.memfd, args.size, prot=mmap.PROT_READ)
    os.close(args.memfd)
    try:
        _child_main(conn, slots, args.slot_bytes, max(1, args.batch))
    except (OSError, EOFError):
        return 0  # the recorder went away mid-message: nothing to tell
    finally:
        with contextlib.suppress(BufferError):
            slots.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
