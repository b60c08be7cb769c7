"""``thermcap bench record`` in its short form. Every mode records every frame. In the analysis
mode, frames the capped detector skips are not a failure; the bench once refused them as one,
and failed on every run. The foxglove-sdk writer is the anchor, measured on the same frames in
the same run, in alternating rounds."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_bench_record_short_with_the_sdk_anchor():
    r = run_cli("bench", "record", "--sizes", "160x128", "--frames", "120", "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    rows = {row["mode"]: row for row in json.loads(r.stdout)}
    assert set(rows) == {"auto", "auto+analysis", "lz4"}
    auto = rows["auto"]
    assert auto["cpu_ms_per_frame"] > 0 and auto["sdk_cpu_ms_per_frame"] > 0
    assert auto["cpu_vs_sdk"] == round(auto["cpu_ms_per_frame"] / auto["sdk_cpu_ms_per_frame"], 3) or \
        abs(auto["cpu_vs_sdk"] - auto["cpu_ms_per_frame"] / auto["sdk_cpu_ms_per_frame"]) < 0.01
    assert abs(auto["ratio"] - auto["sdk_ratio"]) / auto["ratio"] < 0.1  # the same output size, near enough
    # both writers run five times in alternating order (R S S R R S S R R S); the row has each round's ratio
    assert auto["sdk_rounds"] == 5 and len(auto["cpu_vs_sdk_each_round"]) == 5
    assert min(auto["cpu_vs_sdk_each_round"]) <= auto["cpu_vs_sdk"] + 0.01
    assert auto["cpu_vs_sdk_rounds_median"] == sorted(auto["cpu_vs_sdk_each_round"])[2]
    # every run primed the page cache for its output before it was timed, and says what it cost
    assert len(auto["primed_cpu_s_each_run"]) == 10 and all(v >= 0 for v in auto["primed_cpu_s_each_run"])
    assert 0 <= auto["sys_ms_per_frame"] <= auto["cpu_ms_per_frame"]
    assert 0 <= auto["sdk_sys_ms_per_frame"] <= auto["sdk_cpu_ms_per_frame"]


def test_bench_record_takes_more_rounds():
    r = run_cli("bench", "record", "--sizes", "96x64", "--frames", "60", "--rounds", "3", "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    auto = next(row for row in json.loads(r.stdout) if row["mode"] == "auto")
    assert auto["sdk_rounds"] == 3 and len(auto["cpu_vs_sdk_each_round"]) == 3
    assert len(auto["primed_cpu_s_each_run"]) == 6
    bad = run_cli("bench", "record", "--rounds", "0", timeout=60)
    assert bad.returncode == 2 and "--rounds" in bad.stderr


def test_each_writer_runs_in_a_process_of_its_own_and_a_failure_says_why(tmp_path):
    import pytest

    from thermcap.benches.writer_run import run_isolated

    run = run_isolated("recorder", 96, 64, 30, 1, tmp_path)
    assert run.cpu_s_per_frame > 0 and run.bytes > 0
    assert run.primed_cpu_s > 0 and 0 <= run.sys_s_per_frame <= run.cpu_s_per_frame
    assert not any(tmp_path.rglob("*.mcap")), "the run's files are removed"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".prime")] == [], "and the priming file"
    with pytest.raises(ValueError, match="writer must be"):
        run_isolated("ffmpeg", 96, 64, 30, 1, tmp_path)
    blocked = tmp_path / "a-file"
    blocked.write_bytes(b"")  # the child cannot make its folder here: its error comes back
    with pytest.raises(RuntimeError, match="bench recorder run failed"):
        run_isolated("recorder", 96, 64, 30, 1, blocked / "run")
