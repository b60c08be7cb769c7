"""``thermcap bench cdr``: its figures are only given for encoders that agree byte for byte, and
its anchor is rosbags' own encoder, fed the same documents."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from thermcap.benches import cdr
from thermcap.recorder.icd import rosmsg

pytest.importorskip("rosbags", reason="rosbags (the ros2 extra) is the bench's anchor")


def test_the_bench_compares_three_encoders_that_agree():
    from thermcap.cli import cli

    r = CliRunner().invoke(cli, ["bench", "cdr", "--frames", "8", "--repeat", "1", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.output)
    assert [row["message"].split(" (")[0] for row in res["rows"]] == ["sidecar", "target marks", "recorder stats"]
    for row in res["rows"]:
        assert row["mcap_ros2_us"] > 0 and row["rosbags_us"] > 0 and row["x_rosbags"] > 0


def test_a_hand_layout_that_differs_gets_no_figure(monkeypatch):
    good = rosmsg.annotations_message

    def off_by_one(stamp_ns, targets):
        return good(stamp_ns + 1, targets)

    monkeypatch.setattr(rosmsg, "annotations_message", off_by_one)
    with pytest.raises(AssertionError, match="target marks"):
        cdr.bench_cdr(8, 1)


def test_rosbags_reads_what_it_is_given_like_mcap_ros2():
    """The anchor encodes the same fields: nested messages, sequences of numbers and of messages."""
    enc = cdr._rosbags_encoder(rosmsg.SIDECAR.name, rosmsg.SIDECAR.text)
    doc = {"json": "{}", "frame_index": 7, "targets": [{"target_id": "T1", "bbox": [1, 2, 3, 4], "centroid": [2.5, 3.5],
                                                       "max_temp_c": 41.5}], "slew_to_cue_active": True}
    assert enc(doc) == cdr.library_encoder(rosmsg.SIDECAR.name, rosmsg.SIDECAR.text)(doc)
