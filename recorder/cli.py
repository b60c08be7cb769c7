"""The ``thermcap`` command: the root group, and the recorder's own subcommands.

Other packages add their subcommands through the ``thermcap.commands`` and ``thermcap.bench``
entry-point groups (see pyproject.toml), so the recorder never imports the archive or the API.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from importlib.metadata import entry_points
from typing import Any

import click

from recorder import __version__
from recorder.exceptions import ThermcapError

__all__ = ["main", "cli", "bench", "default_root", "fail"]


def default_root() -> str:
    return os.environ.get("THERMCAP_ROOT", "thermcap-data")


def fail(message: str, code: int = 1) -> None:
    click.echo(f"error: {message}", err=True)
    sys.exit(code)


root_option = click.option("--root", default=default_root, show_default="$THERMCAP_ROOT or ./thermcap-data",
                           type=click.Path(file_okay=False), help="Data root (sessions live in ROOT/sessions).")
json_option = click.option("--json", "as_json", is_flag=True, help="Print machine-readable JSON.")


class _PluginGroup(click.Group):
    """A group that also lists the subcommands other packages registered as entry points."""

    def __init__(self, *args: Any, entry_point_group: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._ep_group = entry_point_group
        self._loaded = False

    def _load(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for ep in entry_points(group=self._ep_group):
            if ep.name not in self.commands:
                self.add_command(ep.load(), ep.name)

    def list_commands(self, ctx: click.Context) -> list[str]:
        self._load()
        return super().list_commands(ctx)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        self._load()
        return super().get_command(ctx, name)


@click.group(cls=_PluginGroup, entry_point_group="thermcap.commands",
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="thermcap")
def cli() -> None:
    """Record, archive and serve radiometric thermal camera data (Gray16 on MCAP)."""


@cli.group(cls=_PluginGroup, entry_point_group="thermcap.bench")
def bench() -> None:
    """Benchmarks: each prints ratios against a baseline measured in the same run."""


# -- record ---------------------------------------------------------------------------------
@cli.command()
@click.option("--source", default="sim", show_default=True, help="sim, raw:PATH, or raw:- for stdin.")
@click.option("--duration", type=float, default=None, help="Seconds to record (default: until the input ends or Ctrl-C).")
@click.option("--fps", type=float, default=60.0, show_default=True)
@click.option("--width", type=int, default=640, show_default=True)
@click.option("--height", type=int, default=512, show_default=True)
@click.option("--sensor", "sensor_id", default=None, help="Sensor id used in names (default SIM640 / GRAY16).")
@root_option
@click.option("--session", "session_id", default=None, help="Session id (default: <UTC time>_<sensor>_<random>).")
@click.option("--pace/--no-pace", default=None,
              help="Release frames at --fps (default: on for sim, off for raw: as fast as they arrive).")
@click.option("--timestamps", type=click.Choice(["stream", "arrival"]), default="stream", show_default=True,
              help="raw: 'stream' stamps frame i at start + i/fps (a file or a replay), 'arrival' when it "
                   "arrives (a pipe from a live camera tool).")
@click.option("--seed", type=int, default=0, show_default=True, help="Simulator seed.")
@click.option("--crossover", is_flag=True, help="Simulator: include a dawn/dusk thermal crossover.")
@click.option("--cue-period", type=float, default=20.0, show_default=True, help="Simulator: seconds between radar cues (0: none).")
@click.option("--segment-duration", type=float, default=60.0, show_default=True, help="Rotate segments after this many seconds.")
@click.option("--segment-size", type=float, default=4096.0, show_default=True, help="Rotate segments after this many MiB.")
@click.option("--compression", type=click.Choice(["auto", "zstd", "lz4", "none"]), default="auto", show_default=True,
              help="Chunk compression; auto: zstd-1 up to 25 Mpixel/s, lz4 above (e.g. 1280x1024@60).")
@click.option("--level", type=int, default=None, help="Compression level (default: zstd 1, lz4 0).")
@click.option("--queue", "queue_frames", type=int, default=120, show_default=True, help="Capture queue capacity in frames.")
@click.option("--analysis/--no-analysis", default=True, show_default=True,
              help="Run the hot-spot detector beside recording (fills sidecar targets and contrast grade).")
@click.option("--debug-writer-delay", type=float, default=0.0, hidden=True)
@json_option
def record(source: str, duration: float | None, fps: float, width: int, height: int, sensor_id: str | None,
           root: str, session_id: str | None, pace: bool | None, timestamps: str, seed: int, crossover: bool, cue_period: float,
           segment_duration: float, segment_size: float, compression: str, level: int | None, queue_frames: int,
           analysis: bool, debug_writer_delay: float, as_json: bool) -> None:
    """Record a session: frames + ICD sidecars into rotating, crash-safe MCAP segments."""
    from recorder.mcap_writer import Compression
    from recorder.recorder import Recorder
    from recorder.segments import SegmentPolicy, auto_compression
    from recorder.sources import make_source

    try:
        is_sim = source == "sim"
        src = make_source(source, width=width, height=height, fps=fps, seed=seed, crossover=crossover,
                          cue_period_s=cue_period, paced=(is_sim if pace is None else pace),
                          duration_s=duration if is_sim else None, sensor_id=sensor_id,
                          timestamps=None if is_sim else timestamps)
        if getattr(src, "file_remainder", 0):
            click.echo(f"warning: {source[4:]} is not a whole number of {width}x{height} Gray16 frames "
                       f"({src.file_remainder} bytes left over); the last frame will be reported as truncated",
                       err=True)
        if compression == "auto":
            comp, default_level = auto_compression(width, height, fps)
        else:
            comp, default_level = Compression(compression), (1 if compression == "zstd" else 0)
        policy = SegmentPolicy(max_duration_s=segment_duration or None,
                               max_bytes=int(segment_size * 1024 * 1024) if segment_size else None,
                               compression=comp, compression_level=default_level if level is None else level)
        rec = Recorder(src, root, session_id=session_id, policy=policy, queue_frames=queue_frames,
                       writer_delay_s=debug_writer_delay, analysis=analysis)
    except ThermcapError as exc:
        fail(str(exc))
    except (ValueError, OSError) as exc:
        fail(str(exc))

    if not as_json:
        click.echo(f"session {rec.session_id} -> {rec.session_dir}")
    signal.signal(signal.SIGTERM, lambda *_: rec.stop())
    progress = None if as_json or not sys.stderr.isatty() else _progress_line()
    try:
        result = rec.run(duration_s=None if is_sim else duration, progress=progress)
    except ThermcapError as exc:
        fail(str(exc))
    if progress is not None:
        click.echo("", err=True)
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
    else:
        for p in result.recovered:
            click.echo(f"recovered leftover segment {p}")
        lat = result.write_latency_ms
        fps_eff = result.frames_written / result.wall_s if result.wall_s else 0.0
        click.echo(f"frames: {result.frames_captured} captured, {result.frames_written} written, "
                   f"{result.frames_dropped} dropped  ({fps_eff:.1f} fps over {result.wall_s:.1f} s)")
        timing = result.timing
        click.echo(f"timestamps: {timing.get('time_basis')}  declared {timing.get('declared_fps')} fps, "
                   f"source achieved {timing.get('achieved_fps')} fps, {timing.get('frames_late', 0)} frames late")
        for problem in result.problems:
            if problem != result.error:
                click.secho(f"warning: {problem}", fg="yellow", err=True)
        click.echo(f"segments: {len(result.segments)}  bytes: {sum(s['bytes'] for s in result.segments):,}  "
                   f"write latency p50 {lat['p50']} ms, p99 {lat['p99']} ms")
        if analysis:
            click.echo(f"analysis: {result.frames_written - result.analysis_skipped} frames analysed, "
                       f"{result.analysis_skipped} skipped; {result.events} events")
    if result.error:
        fail(result.error)


def _progress_line():
    import time

    state = {"t": time.monotonic(), "n": 0}

    def show(rec: Any) -> None:
        now = time.monotonic()
        c = rec.counters
        dt = now - state["t"]
        if dt < 0.5:
            return
        rate = (c.frames_written - state["n"]) / dt
        state.update(t=now, n=c.frames_written)
        click.echo(f"\rcaptured {c.frames_captured}  written {c.frames_written}  dropped {c.frames_dropped}  "
                   f"queue {rec.queue_depth}/{rec.queue.maxsize}  {rate:6.1f} fps ", nl=False, err=True)

    return show


# -- info / recover -------------------------------------------------------------------------
@cli.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@json_option
def info(paths: tuple[str, ...], as_json: bool) -> None:
    """Describe segments (NNNN.mcap) or session folders: frames, time span, fps, drops, bytes."""
    from recorder.info import info as get_info

    try:
        data = [get_info(p) for p in paths]
    except ThermcapError as exc:
        fail(str(exc))
    if as_json:
        click.echo(json.dumps(data[0] if len(data) == 1 else data, indent=2))
        return
    for d in data:
        _print_info(d)


def _print_info(d: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console()
    con.print(f"[bold]{d.get('session_id') or d['path']}[/bold]  ({d['path']})")
    if "status" in d:
        con.print(f"status: {d['status']}   sensor: {d.get('sensor')}   segments: {len(d['segments'])}"
                  + (f"   unfinished: {', '.join(d['active_segments'])}" if d["active_segments"] else ""))
        if d.get("hint"):
            con.print(f"[yellow]{d['hint']}[/yellow]")
    con.print(f"frames: {d['frames']}   span: {d['start']} .. {d['end']} ({d['duration_s']:.3f} s)   "
              f"effective fps: {d['effective_fps']}")
    if d.get("time_basis"):
        late = d.get("frames_late") or 0
        con.print(f"timestamps: {d['time_basis']}   declared fps: {d.get('declared_fps')}   "
                  f"source achieved: {d.get('achieved_fps')} fps   "
                  + (f"[yellow]{late} frames late[/yellow]" if late else "0 frames late"))
    dropped = d.get("dropped") or {}
    con.print(f"dropped: {sum(dropped.values()) if dropped else 0} messages {dropped if dropped else ''}")
    con.print(f"bytes: {d['bytes']:,}   chunk compression: {', '.join(d['chunk_compression'])}   "
              f"ratio: {d['compression_ratio']}")
    t = Table("topic", "messages", "bytes (uncompressed)")
    for topic, v in d["topics"].items():
        t.add_row(topic, str(v["messages"]), f"{v['bytes']:,}" if v["bytes"] is not None else "?")
    con.print(t)
    if d.get("error"):
        con.print(f"[red]error during recording: {d['error']}[/red]")


@cli.command()
@click.argument("path", type=click.Path())
@click.option("--keep-original", is_flag=True, help="Keep the .active file after recovery.")
@json_option
def recover(path: str, keep_original: bool, as_json: bool) -> None:
    """Turn interrupted segments (*.mcap.active) into valid, indexed MCAP files."""
    from recorder.recover import recover_path

    try:
        results = recover_path(path, keep_original=keep_original)
    except ThermcapError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename or path}: {exc.strerror or exc}")
    if as_json:
        click.echo(json.dumps([r.to_dict() for r in results], indent=2))
        return
    if not results:
        click.echo(f"nothing to recover under {path}")
    for r in results:
        if r.skipped:
            click.echo(f"{r.source}: {r.stopped_because}; left as it is")
            continue
        click.echo(f"{r.source} -> {r.output}: {r.frames} frames, {r.messages} messages kept, "
                   f"{r.bytes_discarded:,} bytes of cut tail discarded ({r.stopped_because})")


@cli.command()
@click.argument("sessions", nargs=-1, required=True)
@root_option
@click.option("--threshold", type=float, default=5.0, show_default=True, help="K above the local background.")
@click.option("--min-area", type=int, default=4, show_default=True, help="Smallest target, in pixels.")
@click.option("--min-crossover", type=float, default=1.0, show_default=True,
              help="Seconds of grade < 0.3 that make a thermal_crossover event.")
@json_option
def analyze(sessions: tuple[str, ...], root: str, threshold: float, min_area: int, min_crossover: float,
            as_json: bool) -> None:
    """(Re)run hot-spot detection on sessions: analysis.jsonl and events.json beside the segments."""
    from recorder.analyze import analyze_session
    from recorder.reader import resolve_session

    results = []
    for s in sessions:
        try:
            results.append(analyze_session(resolve_session(s, root), threshold_k=threshold, min_area=min_area,
                                           min_crossover_s=min_crossover))
        except ThermcapError as exc:
            fail(str(exc))
    if as_json:
        click.echo(json.dumps(results, indent=2))
        return
    for r in results:
        kinds: dict[str, int] = {}
        for e in r["events"]:
            kinds[e["kind"]] = kinds.get(e["kind"], 0) + 1
        click.echo(f"{r['session']}: {r['frames']} frames, {r['detections']} detections, events {kinds or 'none'}")


@cli.command("import")
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@root_option
@click.option("--session", "session_name", default=None, help="Session id (suffixed -1, -2 ... when files need several).")
@click.option("--session-per-file", is_flag=True, help="One session per file.")
@click.option("--analysis/--no-analysis", default=True, show_default=True, help="Run the hot-spot detector on the frames.")
@click.option("--dji-sdk", default="auto", show_default=True, envvar="THERMCAP_DJI_SDK", metavar="auto|off|PATH",
              help="DJI temperatures by DJI's own code: auto = dji-thermal-cli if on PATH; off; or the path to "
                   "libdirp (.so/.dll) or a dji-thermal-cli executable. Without one, DJI dirp/girp/hirp frames "
                   "import with no temperature and iirp with an approximate one.")
@click.option("--terraref-variant", type=click.Choice(["pipeline", "physical", "plain"]), default="pipeline",
              show_default=True, help="TERRA-REF Planck form for uncalibrated _ir.bin: pipeline = what every published "
                                      "TERRA-REF product used; physical = the measurement equation inverted properly.")
@json_option
def import_cmd(paths: tuple[str, ...], root: str, session_name: str | None, session_per_file: bool, analysis: bool,
               dji_sdk: str, terraref_variant: str, as_json: bool) -> None:
    """Import FLIR JPEG/FFF/SEQ/CSQ, DJI R-JPEG, TERRA-REF _ir.bin and ICD TIFF/raw files (by content)."""
    from rich.progress import Progress

    from recorder.importers.dji_sdk import find_backend
    from recorder.importers.session import import_paths

    backend = find_backend(dji_sdk)
    if backend is not None and not as_json:
        click.echo(f"DJI temperatures by {backend.name}", err=True)

    show = not as_json and sys.stderr.isatty()
    with Progress(disable=not show, transient=True) as bar:
        task = bar.add_task("importing", total=None)
        report = import_paths(list(paths), root, session=session_name, session_per_file=session_per_file,
                              analysis=analysis, dji_sdk=backend,
                              terraref_variant=terraref_variant, on_file=lambda p: bar.advance(task))
    if as_json:
        click.echo(json.dumps({"files": report.files, "failed": report.failed, "truncated": report.truncated,
                               "dji_sdk": backend.name if backend else None,
                               "sessions": [r.to_dict() for r in report.sessions]}, indent=2))
    else:
        for f in report.files:
            c = f["celsius"]
            temp = (f"{c['min']:.2f}..{c['max']:.2f} C (mean {c['mean']:.2f})" + (" approximate" if c.get("approximate") else "")
                    if c else f"no temperature: {f.get('dji_sdk_error') or f.get('celsius_unavailable')}")
            click.echo(f"{f['path']}: {f['format']} {f['layout'] or ''} {f['width']}x{f['height']} {temp} -> {f.get('session_id')}")
        for r in report.sessions:
            click.echo(f"session {r.session_id}: {r.frames_written} frames")
        for f in report.failed:
            click.echo(f"error: {f['error']}", err=True)
        for f in report.truncated:
            click.echo(f"error: {f['error']}", err=True)
    if report.failed or report.truncated or any(not r.ok for r in report.sessions):
        sys.exit(1)


@cli.command("export")
@click.argument("session")
@root_option
@click.option("--to", "kind", type=click.Choice(["celsius-tiff", "kelvin-tiff", "heatmap-png", "icd", "dji-rjpeg"]), required=True)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None, help="Folder (default: SESSION/export/KIND).")
@click.option("--summary", type=click.Choice(["csv", "json"]), default=None,
              help="Also write per-frame surface_temperature statistics.")
@click.option("--palette", default="ironbow", type=click.Choice(["ironbow", "gray", "turbo"]), show_default=True)
@json_option
def export_cmd(session: str, root: str, kind: str, out_dir: str | None, summary: str | None, palette: str,
               as_json: bool) -> None:
    """Export frames as temperature TIFFs, heatmap PNGs, ICD TIFF+JSON pairs or rebuilt DJI R-JPEGs (and a summary)."""
    from recorder.export import export_session
    from recorder.reader import resolve_session

    try:
        d = resolve_session(session, root)
        res = export_session(d, kind, out_dir or d / "export" / kind, summary=summary, palette_name=palette)
    except ThermcapError as exc:
        fail(str(exc))
    click.echo(json.dumps(res, indent=2) if as_json else
               f"{res['files']} files in {res['out']}" + (f"; summary {res['summary']}" if res["summary"] else ""))
    for r in res["refused"][:5]:
        click.echo(f"warning: {r}", err=True)
    if res["refused"]:
        sys.exit(1)


@bench.command("record")
@click.option("--frames", "n_frames", type=int, default=600, show_default=True, help="Frames per measurement.")
@click.option("--sizes", default="640x512,1280x1024", show_default=True)
@click.option("--soak", type=float, default=None, help="Instead: record paced 60 fps for SECONDS and report drops/p99.")
@click.option("--dir", "workdir", type=click.Path(file_okay=False), default=None, help="Where to write (default: a temp folder).")
@json_option
def bench_record(n_frames: int, sizes: str, soak: float | None, workdir: str | None, as_json: bool) -> None:
    """Recorder throughput vs plain zstd-to-file, or a paced soak."""
    from recorder.bench import bench_record as run_bench, run_soak, print_table

    if soak:
        res = run_soak(soak, workdir=workdir)
        click.echo(json.dumps(res, indent=2) if as_json else "\n".join(f"{k}: {v}" for k, v in res.items()))
        if res["frames_dropped"]:
            sys.exit(1)
        return
    try:
        dims = [tuple(int(v) for v in s.lower().split("x")) for s in sizes.split(",")]
    except ValueError:
        fail(f"--sizes must look like 640x512,1280x1024, got {sizes!r}")
    rows = run_bench(dims, n_frames, workdir=workdir, progress=not as_json)
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("import")
@click.option("--frames", "n_frames", type=int, default=300, show_default=True, help="Simulated ICD TIFF files.")
@click.option("--samples", type=click.Path(file_okay=False, exists=True), default=None,
              help="Also real files here (e.g. ../shared/samples), each copied --copies times, one row per format.")
@click.option("--copies", type=int, default=8, show_default=True)
@click.option("--dji-sdk", default="auto", show_default=True, envvar="THERMCAP_DJI_SDK", metavar="auto|off|PATH",
              help="Also time DJI files with this SDK backend.")
@json_option
def bench_import_cmd(n_frames: int, samples: str | None, copies: int, dji_sdk: str, as_json: bool) -> None:
    """Import throughput per format vs reading + hashing the same files."""
    from recorder.bench_import import bench_import, print_table
    from recorder.importers.dji_sdk import find_backend

    rows = bench_import(frames=n_frames, samples=samples, copies=copies, dji_sdk=find_backend(dji_sdk))
    click.echo(json.dumps(rows, indent=2) if as_json else print_table(rows))


@bench.command("analysis")
@click.option("--frames", "n_frames", type=int, default=12, show_default=True, help="Frames per scene.")
@click.option("--samples", type=click.Path(file_okay=False), default=None,
              help="Also run on real files here (e.g. ../shared/samples) and count hot spots per image.")
@click.option("--overlays", type=click.Path(file_okay=False), default=None, help="Write overlay PNGs of those here.")
@json_option
def bench_analysis_cmd(n_frames: int, samples: str | None, overlays: str | None, as_json: bool) -> None:
    """Detector precision/recall/F1 per contrast band vs the simulator's truth, and its speed."""
    from recorder.bench_analysis import bench_analysis, print_table, sample_report

    res = bench_analysis(n_frames)
    if samples:
        res["samples"] = sample_report(samples, overlays)
    if as_json:
        click.echo(json.dumps(res, indent=2))
        return
    click.echo(print_table(res))
    for r in res.get("samples", []):
        click.echo(f"{r['file']:46} {r['format']:16} hot spots {r['hot_spots']}  "
                   + (f"grade {r['grade']}  scene {r['scene_c']} C  largest {r['largest_px']} px" if r["hot_spots"] is not None
                      else r["note"]))


def main() -> None:
    """The console entry point: an error thermcap expected (a ThermcapError) or one from the disk
    (an OSError) is one line naming the file and exit 1, never a traceback."""
    try:
        cli(prog_name="thermcap")
    except ThermcapError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}")
