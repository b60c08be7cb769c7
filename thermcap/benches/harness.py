"""How every benchmark times and reports, so two benches cannot measure one thing two ways.

- ``timed`` and ``best_of``: wall time of a call, once, or the least disturbed of several rounds
  (a micro-benchmark's figure: the machine's noise only ever adds);
- ``alternating``: ours and the anchor in turns, round after round, the ratio the median of each
  round's ratio (a slow minute of the machine lands on both, not on one);
- ``served``: ``thermcap serve`` on a free loopback port, answered before it is used and stopped
  after, for a bench that measures over HTTP;
- ``ratio_line``: the line a bench prints for one pair.

CPU per thread is ``cpu``; a cold page cache made warm before a timed read is ``page_cache``.
"""

from __future__ import annotations

import contextlib
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

__all__ = ["Pair", "alternating", "best_of", "free_port", "ratio_line", "served", "timed"]


def timed(fn: Callable[[], Any]) -> float:
    """Seconds one call of ``fn`` takes."""
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def best_of(fn: Callable[[], Any], calls: int = 1, rounds: int = 5) -> float:
    """Seconds a call, the least of ``rounds`` rounds of ``calls`` calls each."""
    return min(timed(lambda: [fn() for _ in range(calls)]) for _ in range(rounds)) / calls


@dataclass(frozen=True)
class Pair:
    ours_s: float
    anchor_s: float
    ratio: float  # the median of each round's ours / anchor

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def alternating(ours: Callable[[], Any], anchor: Callable[[], Any], rounds: int, warm: bool = True) -> Pair:
    """Ours and the anchor in turns, ``rounds`` times, after one untimed call of each (imports,
    caches, connections)."""
    if warm:
        ours(), anchor()
    pairs = [(timed(ours), timed(anchor)) for _ in range(rounds)]
    return Pair(round(statistics.median(o for o, _ in pairs), 4), round(statistics.median(a for _, a in pairs), 4),
                round(statistics.median(o / a for o, a in pairs), 2))


def ratio_line(name: str, figures: Mapping[str, Any]) -> str:
    """One pair as a bench prints it: a ``Pair.to_dict()``, with its ``goal`` if it has one."""
    line = f"  {name:30} ours {figures['ours_s']:.4f} s  anchor {figures['anchor_s']:.4f} s  " \
           f"ratio {figures['ratio']:.2f}x"
    return line + (f"  (goal {figures['goal']})" if figures.get("goal") else "")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def served(root: Path, *args: str, timeout_s: float = 120.0) -> Iterator[str]:
    """``thermcap serve ROOT`` on a free loopback port, without its access log (nginx, the usual
    anchor, logs nothing either): yields its base URL once ``/healthz`` answers."""
    import httpx

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    # its log to a file: a pipe nobody reads while the bench runs fills and stops the server
    log = tempfile.TemporaryFile()  # noqa: SIM115 - closed below, after the server
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "serve", "--root", str(root), "--port", str(port),
                             "--no-access-log", *args], stdout=subprocess.DEVNULL, stderr=log)
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            if proc.poll() is not None:
                log.seek(0)
                err = log.read().decode(errors="replace")[-2000:]
                raise RuntimeError(f"thermcap serve exited ({proc.returncode}) before it answered: {err}")
            try:
                if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"{url}/healthz did not answer in {timeout_s:.0f} s")
            time.sleep(0.05)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()
