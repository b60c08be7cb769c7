"""``thermcap bench jobs``' short form: both runs archive every session and the figures add up."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from thermcap.cli import cli

pytest.importorskip("distributed", reason="Dask distributed is in the scale extra")


def test_bench_jobs_reports_the_scaling_and_a_capacity_model():
    r = CliRunner().invoke(cli, ["bench", "jobs", "--sessions", "2", "--seconds", "0.6", "--segment-seconds",
                                 "0.2", "--formats", "png16,hdf5", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.output)
    assert res["scaling_2_over_1"] == round(res["wall_s_1_worker"] / res["wall_s_2_worker"], 3)
    assert res["capacity"]["cores_for_100_cameras_8h_a_day_in_24h"] > 0
    assert res["segments_each"] >= 2  # archived as several segment tasks, then one finalize
