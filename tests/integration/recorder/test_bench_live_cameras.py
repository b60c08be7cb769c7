"""``thermcap bench live`` and ``bench cameras`` in their short form: they run, their viewers
receive frames, and the recording drops nothing (the full figures are in
tests/reliability/README.md)."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_bench_live_short():
    r = run_cli("bench", "live", "--seconds", "4", "--live-width", "320", "--json", timeout=180)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["with_viewers"]["frames_dropped"] == 0
    assert len(res["viewers"]) == 2 and all(v.get("frames", 0) > 30 for v in res["viewers"]), res["viewers"]
    assert res["cpu_with_viewers_vs_alone"] > 0


def test_bench_cameras_short():
    r = run_cli("bench", "cameras", "--seconds", "3", "--json", timeout=180)
    res = json.loads(r.stdout)
    assert set(res["mix"]["cameras"]) == {"front", "rear", "aux"}
    cams = res["mix"]["cameras"].values()
    # Zero drops is the benchmark's figure on a quiet host (README); on a shared CI host three live
    # cameras on two cores may drop. What must hold anyway: every frame is written or counted as
    # dropped, and the benchmark fails (exit 1) exactly when something dropped.
    assert all(c["captured"] > 0 and c["written"] + c["dropped"] == c["captured"] for c in cams)
    dropped = res["mix"]["frames_dropped"] + res["anchor"]["frames_dropped"]
    assert r.returncode == (1 if dropped else 0), r.stderr
    assert all(c["cpu_cores"] > 0 for c in res["mix"]["cameras"].values())
