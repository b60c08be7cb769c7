"""``thermcap bench record|import|analysis``: the recorder's benchmarks."""

from __future__ import annotations

import json
import sys

import click

from thermcap.recorder import settings
from thermcap.recorder.cli.options import Number, fail, json_option
from thermcap.recorder.cli.root import bench


@bench.command("record")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=600,
              show_default=True, help="Frames per measurement.")
@click.option("--sizes", default="640x512,1280x1024", show_default=True)
@click.option("--soak", type=Number(minimum=0, above=True, unit="s"), default=None,
              help="Instead: record paced 60 fps for SECONDS and report drops/p99.")
@click.option("--dir", "workdir", type=click.Path(file_okay=False), default=None,
              help="Where to write (default: a temp folder).")
@click.option("--rounds", type=click.IntRange(1, 21), default=5, show_default=True,
              help="Runs of each writer against foxglove-sdk, alternated (more for a tighter verdict).")
@json_option
def bench_record(n_frames: int, sizes: str, soak: float | None, workdir: str | None, rounds: int,
                 as_json: bool) -> None:
    """Recorder throughput vs plain zstd-to-file, or a paced soak."""
    from thermcap.recorder.bench.record import bench_record as run_bench
    from thermcap.recorder.bench.record import print_table, run_soak

    if soak:
        res = run_soak(soak, workdir=workdir)
        click.echo(json.dumps(res, indent=2) if as_json else "\n".join(f"{k}: {v}" for k, v in res.items()))
        if res["frames_dropped"]:
            sys.exit(1)
        return
    try:
        dims = [(int(w), int(h)) for w, h in (s.lower().split("x") for s in sizes.split(","))]
    except ValueError:
        fail(f"--sizes must look like 640x512,1280x1024, got {sizes!r}")
    rows = run_bench(dims, n_frames, workdir=workdir, progress=not as_json, sdk_rounds=rounds)
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("import")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=300,
              show_default=True, help="Simulated ICD TIFF files.")
@click.option("--samples", type=click.Path(file_okay=False, exists=True), default=None,
              help="Also real files here (e.g. ../shared/samples), each copied --copies times, one row per format.")
@click.option("--copies", type=Number(minimum=1, maximum=10_000, integer=True), default=8, show_default=True)
@click.option("--dji-sdk", default=settings.DJI_SDK.default, show_default=True, envvar=settings.DJI_SDK.name,
              metavar="auto|off|PATH",
              help="Also time DJI files with this SDK backend.")
@json_option
def bench_import_cmd(n_frames: int, samples: str | None, copies: int, dji_sdk: str, as_json: bool) -> None:
    """Import throughput per format vs reading + hashing the same files."""
    from thermcap.recorder.bench.imports import bench_import, print_table
    from thermcap.recorder.importers.dji_sdk import find_backend

    rows = bench_import(frames=n_frames, samples=samples, copies=copies, dji_sdk=find_backend(dji_sdk))
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("analysis")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=12,
              show_default=True, help="Frames per scene.")
@click.option("--samples", type=click.Path(file_okay=False), default=None,
              help="Also run on real files here (e.g. ../shared/samples) and count hot spots per image.")
@click.option("--overlays", type=click.Path(file_okay=False), default=None, help="Write overlay PNGs of those here.")
@click.option("--recording-frames", type=Number(minimum=0, maximum=100_000, integer=True), default=400,
              show_default=True, help="Frames of 640x512 (4x at 320x256) per recording of the worst-case scenes "
                                      "with analysis on and off; 0 skips that line.")
@click.option("--rounds", type=Number(minimum=1, maximum=50, integer=True), default=3, show_default=True,
              help="Alternated on/off pairs per scene (the median is reported).")
@click.option("--dir", "workdir", type=click.Path(file_okay=False, exists=True), default=None,
              help="Where the on/off recordings write (default: a temp folder). On a disk whose write-back "
                   "stalls come and go, a RAM folder (/dev/shm) leaves the detector's share alone.")
@json_option
def bench_analysis_cmd(n_frames: int, samples: str | None, overlays: str | None, recording_frames: int,
                       rounds: int, workdir: str | None, as_json: bool) -> None:
    """Detector precision/recall/F1 per contrast band vs the simulator's truth, its speed, and a
    file source recorded with analysis on vs off on the worst-case scenes."""
    from thermcap.recorder.bench.analysis import bench_analysis, print_table, sample_report
    from thermcap.recorder.bench.analysis_handoff import handoff_cpu
    from thermcap.recorder.bench.analysis_recording import print_lines, record_vs_no_analysis

    res = bench_analysis(n_frames)
    if recording_frames:
        res["record_vs_no_analysis"] = record_vs_no_analysis(recording_frames, rounds, workdir)
        res["handoff"] = handoff_cpu(rounds=rounds)
    if samples:
        res["samples"] = sample_report(samples, overlays)
    if as_json:
        click.echo(json.dumps(res, indent=2))
        return
    click.echo(print_table(res))
    for line in print_lines(res.get("record_vs_no_analysis", {})):
        click.echo(line)
    if "handoff" in res:
        hand = res["handoff"]
        click.echo(f"hand-off to the detector's process, {hand['size']}: the recording's CPU "
                   f"{hand['recording_cpu_us_per_frame_batched']} us a frame with answers in batches vs "
                   f"{hand['recording_cpu_us_per_frame_one_message_a_frame']} one message a frame = "
                   f"{hand['batched_vs_one_message_a_frame']}x ({hand['answer_messages_batched']} messages "
                   f"for {hand['frames']} frames); a flat frame, answered here: "
                   f"{hand['recording_cpu_us_per_frame_flat_answered_here']} us")
    for r in res.get("samples", []):
        click.echo(f"{r['file']:46} {r['format']:16} hot spots {r['hot_spots']}  "
                   + (f"grade {r['grade']}  scene {r['scene_c']} C  largest {r['largest_px']} px"
                      if r["hot_spots"] is not None else r["note"]))




@bench.command("cdr")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=100_000, integer=True), default=120,
              show_default=True, help="Simulated frames whose documents are encoded.")
@click.option("--repeat", type=Number(minimum=1, maximum=10_000, integer=True), default=20, show_default=True)
@json_option
def bench_cdr_cmd(n_frames: int, repeat: int, as_json: bool) -> None:
    """The sidecar and the targets' marks, laid out by hand, against mcap_ros2's and rosbags'
    CDR encoders (rosbags the anchor), after checking all three give the same bytes."""
    from thermcap.recorder.bench.cdr import bench_cdr, print_table

    res = bench_cdr(n_frames, repeat)
    click.echo(json.dumps(res, indent=2) if as_json else print_table(res))


@bench.command("cameras")
@click.option("--seconds", type=Number(minimum=0, above=True, maximum=86400, unit="s"), default=10.0,
              show_default=True, help="Seconds per recording.")
@click.option("--dir", "workdir", type=click.Path(file_okay=False), default=None)
@json_option
def bench_cameras_cmd(seconds: float, workdir: str | None, as_json: bool) -> None:
    """Two cameras at 640x512@60 and one at 320x256@30 in one process vs one camera alone:
    drops and CPU per camera."""
    from thermcap.recorder.bench.cameras import bench_cameras, print_table

    res = bench_cameras(seconds, workdir)
    click.echo(json.dumps(res, indent=2) if as_json else print_table(res))
    if res["mix"]["frames_dropped"] or res["anchor"]["frames_dropped"]:
        sys.exit(1)


@bench.command("live")
@click.option("--seconds", type=Number(minimum=0, above=True, maximum=86400, unit="s"), default=10.0,
              show_default=True, help="Seconds per recording.")
@click.option("--viewers", type=Number(minimum=0, maximum=64, integer=True), default=2, show_default=True)
@click.option("--live-fps", type=Number(minimum=0, above=True, maximum=1000, unit="fps"), default=60.0,
              show_default=True)
@click.option("--live-width", type=Number(minimum=0, maximum=16384, integer=True), default=0, show_default=True,
              help="0: full resolution.")
@click.option("--dir", "workdir", type=click.Path(file_okay=False), default=None)
@json_option
def bench_live_cmd(seconds: float, viewers: int, live_fps: float, live_width: int, workdir: str | None,
                   as_json: bool) -> None:
    """Frames/s delivered to live viewers of a 640x512@60 recording, its drops, and the CPU with
    and without viewers."""
    from thermcap.recorder.bench.live import bench_live, print_table

    try:
        res = bench_live(seconds, viewers, live_fps, live_width, workdir)
    except RuntimeError as exc:
        fail(str(exc))
    click.echo(json.dumps(res, indent=2) if as_json else print_table(res))
    if res["with_viewers"]["frames_dropped"]:
        sys.exit(1)


@bench.command("first-record")
@click.option("--duration", type=Number(minimum=0.1, maximum=3600, unit="s"), default=2.0, show_default=True,
              help="Seconds each recording lasts.")
@click.option("--rounds", type=Number(minimum=1, maximum=20, integer=True), default=3, show_default=True,
              help="Cold/warm pairs (the median is reported).")
@click.option("--size", default="640x512", show_default=True, help="The simulator's frame size, WIDTHxHEIGHT.")
@json_option
def bench_first_record_cmd(duration: float, rounds: int, size: str, as_json: bool) -> None:
    """The first recording on an empty numba cache (a first boot) against the next one."""
    from thermcap.recorder.bench.first_record import bench_first_record, print_lines

    try:
        w, h = (int(v) for v in size.lower().split("x"))
    except ValueError:
        fail(f"--size must look like 640x512, got {size!r}")
    res = bench_first_record(duration, rounds, (w, h))
    click.echo(json.dumps(res, indent=2) if as_json else "\n".join(print_lines(res)))


@bench.command("gige")
@click.option("--seconds", type=Number(minimum=0, above=True, maximum=86400, unit="s"), default=10.0,
              show_default=True, help="Seconds per recording.")
@click.option("--camera", default=None,
              help="A GigE Vision camera's address or name (default: Aravis's fake camera, started in a "
                   "loopback-only network namespace; needs root).")
@click.option("--dir", "workdir", type=click.Path(file_okay=False), default=None)
@json_option
def bench_gige_cmd(seconds: float, camera: str | None, workdir: str | None, as_json: bool) -> None:
    """The GigE source's CPU per 640x512 Mono16 frame against a raw pipe's, in the same run."""
    import os

    from thermcap.recorder.bench.gige import INSIDE_ENV, bench_gige, print_lines, run_in_loopback_namespace
    from thermcap.recorder.exceptions import ThermcapError

    if camera is None and not os.environ.get(INSIDE_ENV):
        argv = ["bench", "gige", "--seconds", str(seconds), "--camera", "127.0.0.1",
                *(["--dir", workdir] if workdir else []), *(["--json"] if as_json else [])]
        try:
            sys.exit(run_in_loopback_namespace(argv))
        except RuntimeError as exc:
            fail(str(exc))
    try:
        res = bench_gige(seconds, camera or "127.0.0.1", workdir)
    except ThermcapError as exc:
        fail(str(exc))
    click.echo(json.dumps(res, indent=2) if as_json else "\n".join(print_lines(res)))
