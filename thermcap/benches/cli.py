"""``thermcap bench ...``: every benchmark's command, each printing ratios against an anchor
measured in the same run (``thermcap.benches.harness`` times them one way). ``thermcap.cli``
adds them to its ``bench`` group, where third-party benchmarks join them by entry point."""

from __future__ import annotations

import json
import sys

import click

from thermcap.recorder import settings
from thermcap.recorder.cli.options import Number, fail, json_option
from thermcap.recorder.storage.digest import DEFAULT_DIGEST, DIGESTS


@click.group()
def bench() -> None:
    """The benchmarks' commands; ``thermcap.cli`` adds them to ``thermcap bench``."""


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
    from thermcap.benches.record import bench_record as run_bench
    from thermcap.benches.record import print_table, run_soak

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
    from thermcap.benches.imports import bench_import, print_table
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
    from thermcap.benches.analysis import bench_analysis, print_table, sample_report
    from thermcap.benches.analysis_handoff import handoff_cpu
    from thermcap.benches.analysis_recording import print_lines, record_vs_no_analysis

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
    from thermcap.benches.cdr import bench_cdr, print_table

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
    from thermcap.benches.cameras import bench_cameras, print_table

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
    from thermcap.benches.live import bench_live, print_table

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
    from thermcap.benches.first_record import bench_first_record, print_lines

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

    from thermcap.benches.gige import INSIDE_ENV, bench_gige, print_lines, run_in_loopback_namespace
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


@bench.command("archive")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=60,
              show_default=True, help="Simulated frames per run.")
@click.option("--session", "session_s", type=Number(minimum=0, above=True, maximum=86400, unit="s"), default=None,
              metavar="SECONDS",
              help="Instead: archive a whole 640x512@60 session of this length end to end and report x real time, "
                   "beside the formats' own encode time (the floor) and each format alone.")
@click.option("--formats", default=None, metavar="ID,ID",
              help="--session: the formats to archive (default: the archiver's defaults).")
@click.option("--repeat", type=click.IntRange(1, 20), default=1, show_default=True,
              help="--session: time the whole archive this many times and report the median run (each run listed).")
@click.option("--digest", type=click.Choice(list(DIGESTS)), default=DEFAULT_DIGEST, show_default=True,
              help="--session: the hash of the manifest's proofs, as `thermcap archive --digest`.")
@json_option
def bench_archive(n_frames: int, session_s: float | None, formats: str | None, repeat: int, digest: str,
                  as_json: bool) -> None:
    """Per codec: ratio, encode and decode fps, against Pillow PNG, tifffile LZW and h5py gzip-4."""
    from thermcap.benches.archive import bench_archive as run
    from thermcap.benches.archive import bench_session, print_table

    if session_s:
        res = bench_session(session_s, tuple(formats.split(",")) if formats else None, repeat=repeat, digest=digest)
        click.echo(json.dumps(res, indent=2) if as_json else
                   f"{res['seconds_of_recording']} s of 640x512@60 ({res['frames']} frames), formats "
                   f"{', '.join(res['formats'])}: archived in {res['archive_wall_s']} s = "
                   f"{res['x_real_time']}x real time"
                   + (f" (the median of {repeat} runs: {res['x_real_time_runs']})" if repeat > 1 else "")
                   + f", {res['cpu_ms_per_frame']} CPU ms per frame (at best "
                   f"{res['cpu_bound_x_real_time']}x on {res['cores']} cores); the formats' own encoders alone: "
                   f"{res['floor_x_real_time']}x; one format at a time: {res['x_real_time_one_format']}; "
                   f"writing and reading back alone, {res['formats_cpu_ms_per_frame']} CPU ms per frame "
                   f"{res['format_cpu_ms_per_frame']}: at best {res['formats_bound_x_real_time']}x. The "
                   f"archive's CPU against theirs: {res['cpu_vs_formats']}x (goal <= 1.10x; each run against "
                   f"the floor measured right after it: {res['cpu_vs_formats_rounds']}, median "
                   f"{res['cpu_vs_formats_rounds_median']}x); against the same formats side by side, as the "
                   f"archive runs them: median {res['cpu_vs_formats_together_rounds_median']}x; against theirs plus "
                   f"the one read of the source ({res['source_read_cpu_ms_per_frame']} ms a frame): "
                   f"{res['cpu_vs_formats_and_source_read']}x. Not in these "
                   f"figures: the process's first archive (1 s of frames, imports and compiled kernels loaded), "
                   f"{res['first_archive_of_1_s_wall_s']} s")
        return

    rows = run(n_frames)
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("temporal")
@click.option("--frames", "n_frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=240,
              show_default=True, help="Frames per sequence.")
@click.option("--file", "files", multiple=True, type=click.Path(exists=True, dir_okay=False),
              help="A multi-frame file of your own (FLIR SEQ/CSQ, anything `thermcap import` reads): a row "
                   "with the goal of JPEG-XL e2's ratio. Repeat for more.")
@json_option
def bench_temporal_cmd(n_frames: int, files: tuple[str, ...], as_json: bool) -> None:
    """tpred (temporal prediction) against JPEG-XL e2, JPEG-LS, PNG16 and FFV1 on still, sweeping, cued,
    shaking and gain-stepping views, the samples' and your own real sequences, and its rate in a fresh
    process."""
    from thermcap.benches.temporal import bench_temporal
    from thermcap.recorder.importers import ImportFileError

    try:
        rows = bench_temporal(n_frames, files)
    except ImportFileError as exc:
        raise click.ClickException(str(exc)) from None
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    seqs = [r for r in rows if r["kind"] == "sequence"]
    prev = f"v{seqs[0]['previous_bitstream']}" if seqs else "prev"
    click.echo(f"{'sequence':42} {'tpred':>6} {'jxl e2':>6} {'x jxl':>6} {'jpegls':>6} {'ffv1':>6} {'png16':>6} "
               f"{'fps 1c':>7} {'fps 2c':>7} {prev + ' x jxl':>8} {prev + ' 2c':>6}")
    for r in seqs:
        click.echo(f"{r['sequence']:42} {r['tpred_ratio']:>6} {r['jxl_e2_ratio']:>6} {r['x_jxl_e2']:>6} "
                   f"{r['jpegls_ratio']:>6} {r.get('ffv1_ratio', '-')!s:>6} {r['png16_ratio']:>6} "
                   f"{r['tpred_fps_1_core']:>7} {r['tpred_fps_2_cores']:>7} {r['tpred_previous_x_jxl_e2']:>8} "
                   f"{r['tpred_previous_fps_2_cores']:>6}")
    for r in rows:
        if r["kind"] == "unreadable":
            click.echo(f"left out, a sample that does not import: {r['error']}", err=True)
        if r["kind"] == "fresh_process":
            click.echo(f"{r['sequence']} ({r['frames']} frames {r['size']}, two threads, from the codec's import): "
                       f"{r['fps_2_cores_cached']} fps with the compiled kernels cached "
                       f"(first frame {r['first_frame_s_cached']} s, "
                       f"{r['fps_2_cores_cached_after_start']} fps after it), "
                       f"{r['fps_2_cores_cold_cache']} fps compiling them "
                       f"(first frame {r['first_frame_s_cold_cache']} s); goal {r['goal_fps_2_cores']}")


@bench.command("api")
@click.option("--frames", type=Number(minimum=1, maximum=1_000_000, integer=True), default=300, show_default=True,
              help="Frames in the benchmark session.")
@click.option("--requests", "n_requests", type=Number(minimum=1, maximum=10_000_000, integer=True), default=400,
              show_default=True)
@click.option("--clients", type=Number(minimum=1, maximum=256, integer=True), default=4, show_default=True)
@json_option
def bench_api_cmd(frames: int, n_requests: int, clients: int, as_json: bool) -> None:
    """Frames/s and p50/p99 over real HTTP with concurrent clients; export MB/s; beside disk reads."""
    from thermcap.benches.api import bench_api, print_table

    rows = bench_api(frames, n_requests, clients)
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("jobs")
@click.option("--sessions", type=int, default=1, show_default=True)
@click.option("--seconds", type=float, default=10.0, show_default=True, help="Length of each 640x512@60 session.")
@click.option("--segment-seconds", type=float, default=1.0, show_default=True,
              help="Segment length: a 10 s session of 1 s segments is 10 segment tasks.")
@click.option("--formats", default="png16,tiff-lzw,hdf5", show_default=True)
@click.option("--pin/--no-pin", default=True, show_default=True, help="One core per worker process.")
@json_option
def bench_jobs_cmd(sessions: int, seconds: float, segment_seconds: float, formats: str, pin: bool,
                   as_json: bool) -> None:
    """The same sessions archived as Dask tasks (a task per segment) on one worker and on two: the
    scaling, and a capacity model."""
    from thermcap.benches.jobs import bench_jobs

    res = bench_jobs(sessions, seconds, tuple(f for f in formats.split(",") if f), segment_s=segment_seconds, pin=pin)
    if as_json:
        click.echo(json.dumps(res, indent=2))
        return
    click.echo(f"{sessions} sessions of {seconds:g} s: 1 worker {res['wall_s_1_worker']} s "
               f"({res['x_real_time_1_worker']}x real time), 2 workers {res['wall_s_2_worker']} s "
               f"({res['x_real_time_2_worker']}x): scaling {res['scaling_2_over_1']}x; "
               f"cores for 100 cameras x 8 h a day: {res['capacity']['cores_for_100_cameras_8h_a_day_in_24h']}")


@bench.command("index")
@click.option("--sessions", type=Number(minimum=1, maximum=10_000_000, integer=True), default=100_000,
              show_default=True, help="Synthetic sessions in the catalog.")
@click.option("--frames", type=Number(minimum=1, maximum=1_000_000_000, integer=True), default=10_000_000,
              show_default=True, help="Synthetic frames across them.")
@click.option("--db", "db_url", default=None, metavar="postgresql://...",
              help="A PostgreSQL server to measure on (a fresh database is made there and dropped); default SQLite.")
@json_option
def bench_index_cmd(sessions: int, frames: int, db_url: str | None, as_json: bool) -> None:
    """Index bytes per camera-hour; a catalog page and a frame search at fleet size, p50."""
    from thermcap.benches.index import bench_index, print_table

    res = bench_index(sessions, frames, db_url)
    click.echo(json.dumps(res, indent=2) if as_json else print_table(res))


@bench.command("series")
@click.option("--seconds", type=float, default=60.0, show_default=True, help="Session length at 640x512@60.")
@click.option("--tool", default="box:300,200,339,239", show_default=True)
@json_option
def bench_series_cmd(seconds: float, tool: str, as_json: bool) -> None:
    """A region's series over an archived session (whole frame from the summary, a box from its
    strips) against decoding every frame, in one run; exits 1 if the ways disagree."""
    from thermcap.benches.series import bench_series, print_table

    res = bench_series(seconds, tool)
    click.echo(json.dumps(res, indent=2) if as_json else print_table(res))
    if not res["same_values"]:
        sys.exit(1)


@bench.command("python")
@click.option("--frames", type=click.IntRange(10, 100_000), default=600, show_default=True)
@click.option("--rounds", type=click.IntRange(1, 21), default=5, show_default=True)
@click.option("--hour", is_flag=True,
              help="Also open a real one-hour session (216,000 frames, recorded first: minutes).")
@click.option("--json", "as_json", is_flag=True, help="One JSON document.")
def bench_python_cmd(frames: int, rounds: int, hour: bool, as_json: bool) -> None:
    """The Python API: Zarr endpoint vs h5py, thermcap.open(url) vs a raw GET, to_xarray's open."""
    import json

    from thermcap.benches.harness import ratio_line
    from thermcap.benches.python import bench_python

    res = bench_python(frames=frames, rounds=rounds, hour=hour)
    if as_json:
        click.echo(json.dumps(res, indent=2))
        return
    click.echo(f"{res['frames']} frames {res['size']}, median of {res['rounds']} alternating rounds")
    for name in ("zarr_whole_session_vs_h5py", "zarr2_whole_session_vs_h5py", "first_frame_open_vs_raw_get"):
        click.echo(ratio_line(name, res[name]))
    o = res["to_xarray_open"]
    click.echo(f"  {'to_xarray_open':30} {o['seconds']:.4f} s, {o['frames_read']} frames read  (goal {o['goal']})")
    if "to_xarray_open_one_hour" in res:
        h = res["to_xarray_open_one_hour"]
        click.echo(f"  {'to_xarray_open_one_hour':30} {h['seconds']:.4f} s for {h['frames']:,} frames "
                   f"({h['chunks']:,} chunks), {h['frames_read']} frames read, {h['peak_python_mb']} MB peak; "
                   f"imports {h['imports_s']} s apart  (goal {h['goal']})")


@bench.command("startup")
@click.option("--rounds", type=click.IntRange(1, 51), default=7, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="One JSON document.")
def bench_startup_cmd(rounds: int, as_json: bool) -> None:
    """How fast the command starts: --help against `python -c "import click"`."""
    import json

    from thermcap.benches.python import bench_startup

    res = bench_startup(rounds)
    if as_json:
        click.echo(json.dumps(res, indent=2))
        return
    for name, r in res.items():
        click.echo(f"  {name:24} {r['ours_s'] * 1000:7.1f} ms  import click {r['anchor_s'] * 1000:6.1f} ms  "
                   f"ratio {r['ratio']:.2f}x  (goal {r['goal']})")
