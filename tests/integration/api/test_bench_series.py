"""``thermcap bench series`` in its short form: every way of reading a series gives the numbers
the frame-by-frame path gives, the whole frame decodes nothing, and a box decodes no whole
frame."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_bench_series_short():
    r = run_cli("bench", "series", "--seconds", "1", "--tool", "polygon:100,100,200,120,150,220", "--json",
                timeout=300)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["same_values"] and res["frames"] == 60
    runs = res["runs"]
    assert runs["whole_frame_summary"]["method"] == "summary" and runs["whole_frame_summary"]["frames_decoded"] == 0
    assert runs["box_strips"]["method"] == "strips" and runs["box_strips"]["frames_decoded"] == 0
    assert runs["box_frame_by_frame"]["frames_decoded"] == 60
