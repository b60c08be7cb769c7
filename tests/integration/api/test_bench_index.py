"""``thermcap bench index`` in its short form, on SQLite here and on a real PostgreSQL in the
system tier: the index's bytes come table by table with no row per frame among them, under 10 MB a
camera-hour with a target in every frame, and the
catalog and the frame search answer from the synthetic fleet."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_bench_index_short_on_sqlite():
    r = run_cli("bench", "index", "--sessions", "300", "--frames", "20000", "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    size = res["index_size"]
    assert "frame_blobs" not in size["bytes_by_table"] and "frames" not in size["bytes_by_table"]
    assert size["bytes_per_frame"] > 0
    worst = size["every_frame_a_target"]
    assert "target_seconds" in worst["bytes_by_table"]
    assert worst["bytes_per_camera_hour"] <= size["goal_bytes_per_camera_hour"]  # the goal, in the worst case
    assert worst["frames_file_bytes_per_frame"] > 64  # its two sha256 at least, outside the database
    assert abs(size["bytes_per_camera_hour"] - size["bytes_per_frame"] * 216000) <= 216000 * 0.1
    assert res["catalog_page_p50_ms"] > 0 and res["frame_search_p50_ms"] > 0
    assert res["frame_search_hits_first_page"] > 0  # 5% of 20,000 frames have a target, some above 40 C
