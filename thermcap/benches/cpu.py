"""CPU seconds of the whole process and of single threads (Linux ``/proc``), sampled while
they run, so a benchmark can say what each camera, the writer and the live view cost."""

from __future__ import annotations

import os
import resource
import threading
from pathlib import Path

__all__ = ["ThreadCpu", "process_cpu_s", "process_cpu_split"]

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def process_cpu_s() -> float:
    return process_cpu_split()[0]


def process_cpu_split() -> tuple[float, float]:
    """(user + kernel, kernel) CPU seconds, from one reading: differences of two readings keep
    the kernel's part within the whole (``os.times`` counts in 10 ms ticks, too coarse for that)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime, ru.ru_stime


def _thread_cpu_s(tid: int) -> float | None:
    try:
        fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime (fields 14 and 15)


class ThreadCpu(threading.Thread):
    """Polls the CPU time of the threads it is told about; a thread's last value outlives it."""

    def __init__(self, interval_s: float = 0.2) -> None:
        super().__init__(name="bench-cpu", daemon=True)
        self.interval_s = interval_s
        self.last: dict[int, float] = {}
        self.watch: set[int] = set()
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.wait(self.interval_s):
            self.sample()

    def sample(self) -> None:
        for tid in list(self.watch):
            v = _thread_cpu_s(tid)
            if v is not None:
                self.last[tid] = v

    def stop(self) -> None:
        self._halt.set()
        self.join()

    def of(self, tid: int | None) -> float:
        return round(self.last.get(tid, 0.0), 3) if tid is not None else 0.0
