"""A bounded load on 127.0.0.1: mixed frame, list and export requests while the index is being
rebuilt. Error rate 0; latency percentiles are printed for tests/reliability/README.md."""

from __future__ import annotations

import json
import os
import random
import threading
import time

import httpx
import pytest

from tests.conftest import ApiServer
from tests.support.api_data import make_root

pytestmark = pytest.mark.slow  # a reliability run: CI runs its short form, `-m "not slow"` skips it


def test_mixed_load_while_indexing(tmp_path):
    root = make_root(tmp_path / "root")
    server = ApiServer(root)
    n = int(os.environ.get("THERMCAP_LOAD_REQUESTS", "400"))
    lat: dict[str, list[float]] = {"frame": [], "list": [], "export": []}
    errors: list[str] = []
    lock = threading.Lock()
    stop = threading.Event()

    def indexer():
        with httpx.Client(base_url=server.url, timeout=60) as c:
            while not stop.is_set():
                r = c.post("/api/v1/index", params={"force": True})
                if r.status_code != 200:
                    with lock:
                        errors.append(f"index {r.status_code}")

    def client(seed: int, count: int):
        rng = random.Random(seed)
        with httpx.Client(base_url=server.url, timeout=60) as c:
            for _ in range(count):
                kind = rng.choices(["frame", "list", "export"], weights=[8, 3, 1])[0]
                if kind == "frame":
                    fmt = rng.choice(["raw", "png16", "preview"])
                    url = f"/api/v1/sessions/s-archived/frames/{rng.randrange(60)}?format={fmt}"
                elif kind == "list":
                    url = rng.choice(["/api/v1/sessions", "/api/v1/sessions/s-crossover/frames?max_grade=0.3",
                                      "/api/v1/sessions/s-archived"])
                else:
                    url = "/api/v1/sessions/s-mcap-only/export.mcap"
                t = time.perf_counter()
                r = c.get(url)
                dt = time.perf_counter() - t
                with lock:
                    lat[kind].append(dt)
                    if r.status_code != 200:
                        errors.append(f"{url} {r.status_code}")

    idx = threading.Thread(target=indexer)
    idx.start()
    clients = [threading.Thread(target=client, args=(i, n // 4)) for i in range(4)]
    t0 = time.perf_counter()
    try:
        for c in clients:
            c.start()
        for c in clients:
            c.join()
    finally:
        stop.set()
        idx.join()
        server.stop()
    wall = time.perf_counter() - t0
    assert errors == []

    def pct(v, q):
        v = sorted(v)
        return round(v[min(len(v) - 1, int(q / 100 * (len(v) - 1)))] * 1000, 1) if v else None

    print(json.dumps({"requests": sum(len(v) for v in lat.values()), "seconds": round(wall, 1), "errors": 0,
                      **{k: {"n": len(v), "p50_ms": pct(v, 50), "p99_ms": pct(v, 99)} for k, v in lat.items()}}))
