"""``thermcap bench api``: frames and exports over real HTTP on 127.0.0.1, against nginx and the disk.

A session is recorded and archived into a temporary root, and the server runs as its own process.
Client threads request random frames (``raw`` and ``png16``), one client and then several. In
the same run, with the same client code, nginx serves the same bytes as static files: each
frame's PNG and its raw counts, one file each, and the export's own MCAP. Those are the anchors
of the ratios (goal: png16 p50 <= 2x nginx, raw <= 3x, export.mcap >= 50% of nginx's
throughput). The export is also timed against ``cat`` of the segments from the page cache.
"""

from __future__ import annotations

import random
import shutil
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

from thermcap.benches.harness import served
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_api"]


def _percentile(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, round(q / 100 * (len(values) - 1)))]


ROUNDS = 5  # alternating pairs of rounds, ours then nginx's
UNARCHIVED = "bench-mcap"  # the session left as recorded


def bench_api(frames: int = 300, requests: int = 400, clients: int = 4) -> list[dict[str, Any]]:
    from thermcap.api.db import make_engine
    from thermcap.api.indexing import index_root
    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    base = Path(tempfile.mkdtemp(prefix="thermcap-bench-api-"))
    rows = []
    try:
        Recorder(SimSource(frames=frames, paced=False, seed=5), base, session_id="bench", recover_leftovers=False).run()
        archive_session(DataRoot.of(base).session_dir("bench"), ["png16", "tiff-lzw", "hdf5"])  # the default formats
        # and one left as recorded: frames straight from its MCAP segment, as right after recording
        Recorder(SimSource(frames=frames, paced=False, seed=6), base, session_id=UNARCHIVED,
                 recover_leftovers=False).run()
        engine = make_engine(f"sqlite:///{DataRoot.of(base).index_db}")
        from thermcap.api.db import migrate

        migrate(engine)
        index_root(engine, base)
        # no access log, as nginx here (access_log off): the same work on both sides
        with served(base) as url:
            docroot = _static_copies(url, base, frames)
            nginx = _start_nginx(docroot, base)
            ratios: dict[str, Any] = {}
            anchor_raw_p50: list[float] = []
            try:
                for fmt in ("raw", "png16"):
                    # alternating rounds, the median p50 of each: the machine is shared and noisy
                    # (five pairs; the ratio is the median of the pairs' ratios, so a slow spell
                    # that covers one pair moves neither side alone)
                    ours_p50, anchor_p50 = [], []
                    for _ in range(ROUNDS):
                        ours = _frames_over_http(url, fmt, frames, requests // 2, 1)
                        ours_p50.append(ours["p50_ms"])
                        if nginx is not None:
                            anchor = _frames_over_http(nginx.url, fmt, frames, requests // 2, 1, static=True)
                            anchor_p50.append(anchor["p50_ms"])
                    rows.append({**ours, "p50_ms": statistics.median(ours_p50), "rounds": ROUNDS})
                    rows.append(_frames_over_http(url, fmt, frames, requests, clients))
                    if nginx is not None:
                        rows.append({**anchor, "p50_ms": statistics.median(anchor_p50), "rounds": ROUNDS})
                        rows.append(_frames_over_http(nginx.url, fmt, frames, requests, clients, static=True))
                        ratios[f"{fmt}_p50_vs_nginx"] = round(statistics.median(
                            a / b for a, b in zip(ours_p50, anchor_p50, strict=True)), 2)
                    if fmt == "raw":
                        anchor_raw_p50 = anchor_p50
                # a session not archived yet: frames in order (a player, a scrubber), then at random
                for in_order in (True, False):
                    rows.append(_frames_over_http(url, "raw", frames, requests // 2, 1, session=UNARCHIVED,
                                                  in_order=in_order))
                    ratios[f"unarchived_raw_{'in_order' if in_order else 'random'}_p50_vs_nginx"] = round(
                        rows[-1]["p50_ms"] / statistics.median(anchor_raw_p50), 2) if anchor_raw_p50 else None
                rows.append(_disk_frames(base, frames, requests))
                export_rows = _export(url, base, nginx)
                rows += export_rows
                ratios.update(export_rows[-1].get("ratios", {}))
            finally:
                if nginx is not None:
                    nginx.stop()
            rows.append({"what": "ratios (same run, same client)", "ratios": ratios,
                         "nginx": "missing: apt-get install nginx-light" if nginx is None else "1 worker, sendfile"})
    finally:
        shutil.rmtree(base, ignore_errors=True)
    return rows


def _static_copies(url: str, base: Path, frames: int) -> Path:
    """The bytes the API serves, as files for nginx: each frame's PNG and raw counts (fetched
    from the API itself, so they are the same bytes), and the export's MCAP."""
    docroot = base / "static"
    for sub in ("png16", "raw"):
        (docroot / sub).mkdir(parents=True)
    with httpx.Client(base_url=url, timeout=60) as c:
        for n in range(frames):
            for fmt in ("png16", "raw"):
                (docroot / fmt / f"{n}.{'png' if fmt == 'png16' else 'raw'}").write_bytes(
                    c.get(f"/api/v1/sessions/bench/frames/{n}", params={"format": fmt}).content)
        with c.stream("GET", "/api/v1/sessions/bench/export.mcap") as r, open(docroot / "export.mcap", "wb") as f:
            for chunk in r.iter_bytes():
                f.write(chunk)
    return docroot


def _start_nginx(docroot: Path, base: Path) -> Any:
    from thermcap.benches.nginx import Nginx, find_nginx

    if find_nginx() is None:
        return None
    return Nginx(docroot, base / "nginx")


def _frames_over_http(url: str, fmt: str, frames: int, requests: int, clients: int,
                      static: bool = False, session: str = "bench", in_order: bool = False) -> dict[str, Any]:
    lat: list[float] = []
    lock = threading.Lock()
    rng = random.Random(1)
    todo = [i % frames for i in range(requests)] if in_order else [rng.randrange(frames) for _ in range(requests)]
    errors = [0]

    def worker(items: list[int]) -> None:
        with httpx.Client(base_url=url, timeout=30) as c:
            for n in items:
                t = time.perf_counter()
                r = c.get(f"/{fmt}/{n}.{'png' if fmt == 'png16' else 'raw'}") if static else \
                    c.get(f"/api/v1/sessions/{session}/frames/{n}", params={"format": fmt})
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
    what = f"nginx: the same {fmt} file" if static else f"frame format={fmt} over HTTP"
    if session == UNARCHIVED:
        what = f"not archived: format={fmt}, {'in order' if in_order else 'at random'}"
    return {"what": what,
            "clients": clients, "requests": requests,
            "fps": round(requests / wall, 1), "p50_ms": round(_percentile(lat, 50) * 1000, 2),
            "p99_ms": round(_percentile(lat, 99) * 1000, 2), "errors": errors[0]}


def _disk_frames(base: Path, frames: int, requests: int) -> dict[str, Any]:
    from thermcap.archive.reading.zip_directory import read_zip_file

    zips = sorted((DataRoot.of(base).session_dir("bench") / "archive" / "png16").glob("*.zip"))
    spans = [(z, int(off), int(n)) for z, e in ((z, read_zip_file(z)) for z in zips)
             for off, n in zip(e.offset, e.length, strict=True)]
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


def _stream_mb_s(url: str, path: str, repeat: int = 3) -> tuple[float, int]:
    best, got = 0.0, 0
    for _ in range(repeat):  # the best of a few: the page cache and the first connection settle
        t = time.perf_counter()
        got = 0
        with httpx.stream("GET", url + path, timeout=120) as r:
            for chunk in r.iter_bytes():
                got += len(chunk)
        best = max(best, got / (time.perf_counter() - t) / 1e6)
    return best, got


def _export(url: str, base: Path, nginx: Any) -> list[dict[str, Any]]:
    segs = sorted(DataRoot.of(base).session_dir("bench").glob("*.mcap"))
    t = time.perf_counter()
    n = 0
    for s in segs:
        with open(s, "rb") as f:
            while chunk := f.read(1 << 20):
                n += len(chunk)
    disk = n / (time.perf_counter() - t) / 1e6
    http = anchor = 0.0
    for _ in range(3):  # alternating, the best of each
        h, got = _stream_mb_s(url, "/api/v1/sessions/bench/export.mcap", repeat=1)
        http = max(http, h)
        if nginx is not None:
            anchor = max(anchor, _stream_mb_s(nginx.url, "/export.mcap", repeat=1)[0])
    rows: list[dict[str, Any]] = [{"what": "export.mcap (whole session) over HTTP", "mb_per_s": round(http, 1),
                                   "bytes": got}]
    ratios = {"export_vs_cat": round(http / disk, 3) if disk else None}
    if nginx is not None:
        rows.append({"what": "nginx: the same export.mcap file", "mb_per_s": round(anchor, 1), "bytes": got})
        ratios["export_vs_nginx"] = round(http / anchor, 3) if anchor else None
    rows.append({"what": "segment files read from disk (cat, page cache)", "mb_per_s": round(disk, 1), "bytes": n,
                 "export_vs_disk": round(disk / http, 2) if http else None, "ratios": ratios})
    return rows


def print_table(rows: list[dict[str, Any]]) -> str:
    out = []
    for r in rows:
        if "ratios" in r and "mb_per_s" not in r:
            out.append("ratios: " + ", ".join(f"{k} {v}" for k, v in r["ratios"].items()) + f"  (nginx: {r['nginx']})")
        elif "fps" in r:
            out.append(f"{r['what']:44} {r['fps']:>8} req/s  p50 {r['p50_ms']:>7} ms  p99 {r['p99_ms']:>7} ms  "
                       f"clients {r['clients']}  errors {r['errors']}")
        else:
            out.append(f"{r['what']:44} {r['mb_per_s']:>8} MB/s" + (f"  (disk is {r['export_vs_disk']}x the export)"
                                                                    if r.get("export_vs_disk") else ""))
    return "\n".join(out)

