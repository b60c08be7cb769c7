"""`thermcap bench first-record` runs its pairs for real: the cold recording on an empty kernel
cache compiled beside it, the warm one loaded them, and both `ls` lines match the frames' span."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_cli

pytestmark = pytest.mark.integration


def test_the_first_record_bench_pairs_a_cold_and_a_warm_recording():
    r = run_cli("bench", "first-record", "--rounds", "1", "--duration", "1", "--size", "160x128", "--json",
                timeout=900)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["cold_kernels"] == ["warming"]
    assert [row["kernels"] for row in res["warm"]] == ["compiled"]
    assert res["ls_off_span_s"] < 0.05
    assert res["cold_vs_warm"] == pytest.approx(res["cold_wall_s"] / res["warm_wall_s"], rel=0.01)
