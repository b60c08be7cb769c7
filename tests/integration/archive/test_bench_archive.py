"""The archive benchmarks' short forms: each runs end to end and reports the figures its README
table is made from, with every codec checked bit-exact inside the benchmark itself."""

from __future__ import annotations

import json

from click.testing import CliRunner

from thermcap.archive.codecs.tpred.codec import BITSTREAM_VERSION
from thermcap.cli import cli


def test_bench_temporal_reports_every_sequence_against_its_anchors():
    r = CliRunner().invoke(cli, ["bench", "temporal", "--frames", "8", "--json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    seqs = [row for row in rows if row["kind"] == "sequence"]
    assert {row["sequence"] for row in seqs} >= {
        "patrol sweep 10 deg/s", "still (NETD + column FPN)", "shutter (NUC) every 0.5 s",
        "temporal noise above detail (NETD 400 mK)", "sub-pixel shake 0.5 px", "patrol sweep 10 deg/s + shake 0.5 px",
        "AGC gain step (+-5 %) every 1 s"}
    for row in seqs:
        assert row["tpred_ratio"] > 0 and row["jxl_e2_ratio"] > 0 and row["tpred_fps_2_cores"] > 0
        assert abs(row["x_jxl_e2"] - row["tpred_ratio"] / row["jxl_e2_ratio"]) < 0.002  # of the unrounded ratios
        assert row["jpegls_ratio"] > 1 and abs(row["x_jpegls"] - row["tpred_ratio"] / row["jpegls_ratio"]) < 0.002
        assert row["bitstream"] == BITSTREAM_VERSION and row["previous_bitstream"] == BITSTREAM_VERSION - 1
        assert row["tpred_previous_ratio"] > 0 and row["tpred_previous_fps_2_cores"] > 0
    # the rate in a new interpreter, with the kernels' cache as installed and with an empty one,
    # for a steady pan and a shaking one (its filters' fit and pass)
    fresh_rows = [row for row in rows if row["kind"] == "fresh_process"]
    assert [row["sequence"] for row in fresh_rows] == ["patrol sweep 10 deg/s, a fresh process",
                                                       "patrol sweep 10 deg/s + shake 0.5 px, a fresh process"]
    for fresh in fresh_rows:
        assert fresh["frames"] == 8 and fresh["size"] == "640x512" and fresh["goal_fps_2_cores"] == 120
        assert fresh["fps_2_cores_cached"] > 0 and fresh["fps_2_cores_cold_cache"] > 0
        runs = fresh["fps_2_cores_cached_runs"]  # the median of three processes is the figure
        assert len(runs) == 3 and runs == sorted(runs) and fresh["fps_2_cores_cached"] == runs[1]
        # compiling costs more than loading what was compiled
        assert fresh["first_frame_s_cold_cache"] > fresh["first_frame_s_cached"]
        # the start left out, the rate is the higher one
        assert fresh["fps_2_cores_cached_after_start"] > fresh["fps_2_cores_cached"]


def test_bench_temporal_measures_the_users_own_sequence_and_names_a_file_it_cannot_read(samples, tmp_path):
    """Issue 40: the goal on real sequences is the user's file, so ``--file`` makes it a row (a
    SEQ here: the FFF sample three times, as a camera writes them back to back)."""
    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "three.seq"
    seq.write_bytes(one * 3)
    r = CliRunner().invoke(cli, ["bench", "temporal", "--frames", "4", "--file", str(seq), "--json"])
    assert r.exit_code == 0, r.output
    (row,) = [row for row in json.loads(r.output) if row["sequence"].startswith("real three.seq")]
    assert row["frames"] == 3 and row["goal_x_jxl_e2"] == 1.0 and row["tpred_ratio"] > 1
    bad = tmp_path / "notes.txt"
    bad.write_text("not a thermal file")
    r = CliRunner().invoke(cli, ["bench", "temporal", "--frames", "4", "--file", str(bad)])
    assert r.exit_code == 1 and "notes.txt" in r.output and "Traceback" not in r.output


def test_bench_archive_session_reports_x_real_time_beside_its_floors():
    r = CliRunner().invoke(cli, ["bench", "archive", "--session", "0.5", "--formats", "png16,hdf5", "--repeat", "3",
                                 "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.output)
    assert res["frames"] == 30 and res["formats"] == ["png16", "hdf5"]
    # three timed runs, each listed; the one reported is their median
    runs = res["x_real_time_runs"]
    assert len(runs) == 3 == len(res["cpu_ms_per_frame_runs"]) and res["x_real_time"] == sorted(runs)[1]
    assert res["first_archive_of_1_s_wall_s"] > 0  # the untimed warm-up ran, and is reported apart
    # each timed run's page cache was primed first, untimed, and what that cost is listed
    assert len(res["primed_cpu_s_each_run"]) == 3 and all(v >= 0 for v in res["primed_cpu_s_each_run"])
    assert res["x_real_time"] > 0 and res["cpu_bound_x_real_time"] >= res["x_real_time"] * 0.5
    assert set(res["x_real_time_one_format"]) == {"png16", "hdf5"} and res["compression_ratio"]["hdf5"] > 1
    # each format's own writing and reading CPU, and the bound they set on 2x real time
    cpu = res["format_cpu_ms_per_frame"]
    assert set(cpu) == {"png16", "hdf5"} and all(v["write"] > 0 and v["read"] > 0 for v in cpu.values())
    total = sum(v["write"] + v["read"] for v in cpu.values())
    assert abs(res["formats_cpu_ms_per_frame"] - total) < 0.05
    # each run against the floor round measured right after it, and the median of those ratios
    paired = res["cpu_vs_formats_rounds"]
    assert len(paired) == 3 and all(v > 0 for v in paired)
    assert res["cpu_vs_formats_rounds_median"] == sorted(paired)[1]
    # the same against the formats run side by side as the archive runs them, each round after its run
    together = res["formats_together_cpu_ms_per_frame_rounds"]
    assert len(together) == 3 and all(v > 0 for v in together)
    ratios = res["cpu_vs_formats_together_rounds"]
    assert len(ratios) == 3 and res["cpu_vs_formats_together_rounds_median"] == sorted(ratios)[1]
    for (cpu_ms, t), ratio in zip(zip(res["cpu_ms_per_frame_runs"], together, strict=True), ratios, strict=True):
        assert abs(cpu_ms / t - ratio) < 0.01
    assert res["formats_bound_x_real_time"] == round(1000 / 60 * res["cores"] / res["formats_cpu_ms_per_frame"], 3) \
        or abs(res["formats_bound_x_real_time"] - 1000 / 60 * res["cores"] / total) < 0.01


def test_bench_archive_codecs_sets_the_archive_s_lzw_beside_tifffile_s():
    """The tiff-lzw row is the format's own encoder (archive.lzw), its anchor tifffile with
    imagecodecs' LZW on the same frames: the same kind of stream, so the same size within 0.2%."""
    r = CliRunner().invoke(cli, ["bench", "archive", "--frames", "2", "--json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    for frames in {row["frames"] for row in rows}:
        by = {row["codec"]: row for row in rows if row["frames"] == frames}
        ours, theirs = by["tiff-lzw + predictor (archive.lzw)"], by["tifffile LZW + predictor (baseline)"]
        assert ours["kind"] == "thermcap" and theirs["kind"] == "baseline"
        assert abs(ours["ratio"] / theirs["ratio"] - 1) < 0.002 and ours["encode_fps"] > 0


def test_the_samples_sequences_are_found_at_any_depth_and_a_damaged_one_is_left_out_with_its_reason(
        samples, tmp_path, monkeypatch):
    import thermcap.benches.archive as bench
    from thermcap.benches.temporal import real_sequences

    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    (tmp_path / "flir" / "seq").mkdir(parents=True)
    (tmp_path / "flir" / "seq" / "two.seq").write_bytes(one * 2)
    (tmp_path / "flir" / "still.fff").write_bytes(one)  # one frame: a still, not a sequence
    (tmp_path / "flir" / "cut.csq").write_bytes(b"FFF\x00" + b"\x00" * 60)
    monkeypatch.setattr(bench, "SAMPLES", tmp_path)
    unreadable: dict[str, str] = {}
    found = real_sequences(limit=8, unreadable=unreadable)
    assert list(found) == ["real two.seq 640x512"] and len(found["real two.seq 640x512"]) == 2
    cut = str(tmp_path / "flir" / "cut.csq")
    assert list(unreadable) == [cut] and "cut.csq" in unreadable[cut]


def test_the_formats_floor_compares_every_frame_it_reads_back(tmp_path):
    """The floor is a verifying read, as the archive's is: a format whose reader gives back other
    pixels or another sidecar than were written fails the benchmark instead of setting its floor."""
    import dataclasses

    import numpy as np
    import pytest

    from thermcap.archive.formats import ArchiveContext, get_format
    from thermcap.benches.archive import format_cpu, formats_together_cpu, verify_read
    from thermcap.recorder.storage.reader import SessionFrame

    rng = np.random.default_rng(5)
    frames = [SessionFrame(i, "0000.mcap", 1_000_000_000 + i, rng.integers(0, 1 << 14, (16, 24), np.uint16),
                           b'{"capture": {}}') for i in range(4)]
    assert all(v > 0 for v in format_cpu("png16", frames, tmp_path, 1))
    assert formats_together_cpu(("png16", "hdf5"), frames, tmp_path, 1, 2) > 0
    fmt = get_format("png16")
    out = tmp_path / "copy"
    out.mkdir()
    files = [r.path for r in fmt.write(iter(frames), out, ArchiveContext(session_id="t", total_frames=4,
                                                                           frames_per_segment={"0000.mcap": 4}))]
    verify_read("png16", fmt, out, files, frames)
    changed = frames[2].pixels.copy()
    changed[3, 7] ^= 1
    with pytest.raises(RuntimeError, match="frame 2 read back differs"):
        verify_read("png16", fmt, out, files, [*frames[:2], dataclasses.replace(frames[2], pixels=changed), frames[3]])
    with pytest.raises(RuntimeError, match="frame 1 read back differs"):
        verify_read("png16", fmt, out, files, [frames[0], dataclasses.replace(frames[1], sidecar=b"{}"), *frames[2:]])
    with pytest.raises(RuntimeError, match="4 frames read back of 5"):
        verify_read("png16", fmt, out, files, [*frames, frames[0]])
