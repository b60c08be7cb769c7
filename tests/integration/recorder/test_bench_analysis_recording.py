"""``thermcap bench analysis``'s recording line in its short form: every worst-case scene at both
sizes recorded with analysis on and off, alternated, each round's ratio beside the medians' ratio,
every frame analysed (a file source waits for the detector)."""

from __future__ import annotations

import statistics

from thermcap.benches.analysis_recording import SCENES, SIZES, print_lines, record_vs_no_analysis


def test_each_scene_is_recorded_with_and_without_analysis_and_each_round_compared(tmp_path):
    res = record_vs_no_analysis(frames_640=6, rounds=2, workdir=str(tmp_path))
    assert set(res) == {f"{name}_{w}x{h}" for name in SCENES for w, h in SIZES}
    for row in res.values():
        assert row["fps_with_analysis"] > 0 and row["fps_without"] > 0 and row["goal"] == 0.5
        assert abs(row["ratio"] - row["fps_with_analysis"] / row["fps_without"]) < 0.01
        assert len(row["ratio_rounds"]) == 2  # rounded to 3 places, as the median is
        assert abs(row["ratio_rounds_median"] - statistics.median(row["ratio_rounds"])) <= 0.0015
        assert row["frames_skipped"] == 0 and row["runner"] in ("process", "thread")
    assert len(print_lines(res)) == len(res) + 1


def test_the_hand_off_line_measures_batched_answers_against_one_message_a_frame():
    """Its short form: real child processes, the recording's CPU a frame both ways, and the
    batched child sending fewer messages than frames (it is behind through a burst)."""
    from thermcap.benches.analysis_handoff import handoff_cpu

    res = handoff_cpu(frames=200, rounds=1, size=(160, 128))
    assert res["size"] == "160x128" and res["frames"] == 200 and res["rounds"] == 1
    assert res["recording_cpu_us_per_frame_batched"] > 0 and res["recording_cpu_us_per_frame_one_message_a_frame"] > 0
    assert abs(res["batched_vs_one_message_a_frame"] - res["recording_cpu_us_per_frame_batched"]
               / res["recording_cpu_us_per_frame_one_message_a_frame"]) < 0.01
    assert 0 < res["answer_messages_batched"] <= 200
    assert res["recording_cpu_us_per_frame_flat_answered_here"] > 0


def test_the_recordings_go_where_dir_says_and_a_missing_dir_is_named(tmp_path, monkeypatch):
    import tempfile

    from click.testing import CliRunner

    from thermcap.cli import cli

    used: list[str | None] = []
    real = tempfile.TemporaryDirectory

    def spy(*args, **kwargs):
        used.append(kwargs.get("dir"))
        return real(*args, **kwargs)

    monkeypatch.setattr(tempfile, "TemporaryDirectory", spy)
    ok = CliRunner().invoke(cli, ["bench", "analysis", "--frames", "2", "--recording-frames", "2", "--rounds", "1",
                                  "--dir", str(tmp_path), "--json"])
    assert ok.exit_code == 0, ok.output
    assert str(tmp_path) in used and not list(tmp_path.iterdir())  # written there, and cleaned up
    bad = CliRunner().invoke(cli, ["bench", "analysis", "--dir", str(tmp_path / "missing")])
    assert bad.exit_code == 2 and "--dir" in bad.output
