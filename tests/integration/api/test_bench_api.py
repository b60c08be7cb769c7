"""``thermcap bench api`` in its short form: the server, nginx serving the same bytes, and the
ratios between them from one run, and frames of a session not archived yet. Every frame is
answered; the ratios are there and positive."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_cli
from thermcap.benches.nginx import find_nginx


@pytest.mark.skipif(find_nginx() is None, reason="nginx is not installed (.ci/run installs nginx-light)")
def test_bench_api_against_nginx_short():
    r = run_cli("bench", "api", "--frames", "20", "--requests", "20", "--clients", "2", "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert all(row.get("errors", 0) == 0 for row in rows)
    ratios = rows[-1]["ratios"]
    for key in ("raw_p50_vs_nginx", "png16_p50_vs_nginx", "export_vs_nginx", "export_vs_cat",
                "unarchived_raw_in_order_p50_vs_nginx", "unarchived_raw_random_p50_vs_nginx"):
        assert ratios[key] and ratios[key] > 0, key
    # the session left as recorded is served from its MCAP segment, every request answered
    unarchived = [row for row in rows if row["what"].startswith("not archived")]
    assert [row["requests"] for row in unarchived] == [10, 10]
    assert any(row["what"].startswith("nginx: the same png16") for row in rows)
