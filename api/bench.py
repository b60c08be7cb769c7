"""``thermcap bench api``: frames and exports over real HTTP on 127.0.0.1, against the disk.

A session is recorded and archived into a temporary root, the server runs as its own process,
and client threads request random frames (``raw`` and ``png16``) concurrently; beside it, in the
same run, the same frames' bytes are read straight from the archive files on disk. The MCAP
export is timed against reading the session's segment files.
"""

from __future__ import annotations

import random
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

__all__ = ["bench_api"]


def _percentile(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, round(q / 100 * (len(values) - 1)))]


def bench_api(frames: int = 300, requests: int = 400, clients: int = 4) -> list[dict[str, Any]]:
    from api.db import make_engine
    from api.indexing import index_root
    from archive.archiver import archive_session
    from recorder.capture.recorder import Recorder
    from recorder.capture.sources.sim import SimSource

    base = Path(tempfile.mkdtemp(prefix="thermcap-bench-api-"))
    rows = []
    try:
        Recorder(SimSource(frames=frames, paced=False, seed=5), base, session_id="bench", recover_leftovers=False).run()
        archive_session(base / "sessions" / "bench", ["png16"])
        engine = make_engine(f"sqlite:///{base / 'index.sqlite'}")
        from api.db import migrate

        migrate(engine)
        index_root(engine, base)
        import socket
        import subprocess
        import sys

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        proc = subprocess.Popen([sys.executable, "-m", "recorder", "serve", "--root", str(base), "--port", str(port)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        url = f"http://127.0.0.1:{port}"
        for _ in range(300):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        try:
            for fmt in ("raw", "png16"):
                rows.append(_frames_over_http(url, fmt, frames, requests // 2, 1))
                rows.append(_frames_over_http(url, fmt, frames, requests, clients))
            rows.append(_disk_frames(base, frames, requests))
            rows += _export(url, base)
        finally:
            proc.terminate()
            proc.wait(10)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    return rows


def _frames_over_http(url: str, fmt: str, frames: int, requests: int, clients: int) -> dict[str, Any]:
    lat: list[float] = []
    lock = threading.Lock()
    rng = random.Random(1)
    todo = [rng.randrange(frames) for _ in range(requests)]
    errors = [0]

    def worker(items: list[int]) -> None:
        with httpx.Client(base_url=url, timeout=30) as c:
            for n in items:
                t = time.perf_counter()
                r = c.get(f"/api/v1/sessions/bench/frames/{n}", params={"format": fmt})
                dt = time.perf_counter() - t
                with lock:
                    lat.append(dt)
                    errors[0] += r.status_code != 200

    threads = [threading.Thread(target=worker, args=(todo[i::clients],)) for i in range(clients)]
    t = time.perf_counter()
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    wall = time.perf_counter() - t
    return {"what": f"frame format={fmt} over HTTP", "clients": clients, "requests": requests,
            "fps": round(requests / wall, 1), "p50_ms": round(_percentile(lat, 50) * 1000, 2),
            "p99_ms": round(_percentile(lat, 99) * 1000, 2), "errors": errors[0]}


def _disk_frames(base: Path, frames: int, requests: int) -> dict[str, Any]:
    from api.indexing import zip_entries

    zips = sorted((base / "sessions" / "bench" / "archive" / "png16").glob("*.zip"))
    spans = [(z, off, info.file_size) for z in zips for info, off in zip_entries(z) if info.filename.endswith(".png")]
    rng = random.Random(1)
    lat = []
    t0 = time.perf_counter()
    for _ in range(requests):
        z, off, size = spans[rng.randrange(len(spans))]
        t = time.perf_counter()
        with open(z, "rb") as f:
            f.seek(off)
            f.read(size)
        lat.append(time.perf_counter() - t)
    wall = time.perf_counter() - t0
    return {"what": "same PNG bytes read from disk (baseline)", "clients": 1, "requests": requests,
            "fps": round(requests / wall, 1), "p50_ms": round(_percentile(lat, 50) * 1000, 3),
            "p99_ms": round(_percentile(lat, 99) * 1000, 3), "errors": 0}


def _export(url: str, base: Path) -> list[dict[str, Any]]:
    segs = sorted((base / "sessions" / "bench").glob("*.mcap"))
    t = time.perf_counter()
    n = 0
    for s in segs:
        with open(s, "rb") as f:
            while chunk := f.read(1 << 20):
                n += len(chunk)
    disk = n / (time.perf_counter() - t) / 1e6
    t = time.perf_counter()
    got = 0
    with httpx.stream("GET", url + "/api/v1/sessions/bench/export.mcap", timeout=120) as r:
        for chunk in r.iter_bytes():
            got += len(chunk)
    http = got / (time.perf_counter() - t) / 1e6
    return [{"what": "export.mcap (whole session) over HTTP", "mb_per_s": round(http, 1), "bytes": got},
            {"what": "segment files read from disk (baseline)", "mb_per_s": round(disk, 1), "bytes": n,
             "export_vs_disk": round(disk / http, 2) if http else None}]


def print_table(rows: list[dict[str, Any]]) -> str:
    out = []
    for r in rows:
        if "fps" in r:
            out.append(f"{r['what']:44} {r['fps']:>8} req/s  p50 {r['p50_ms']:>7} ms  p99 {r['p99_ms']:>7} ms  "
                       f"clients {r['clients']}  errors {r['errors']}")
        else:
            out.append(f"{r['what']:44} {r['mb_per_s']:>8} MB/s" + (f"  (disk is {r['export_vs_disk']}x the export)"
                                                                    if r.get("export_vs_disk") else ""))
    return "\n".join(out)

