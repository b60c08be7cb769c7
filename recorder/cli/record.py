"""``thermcap record``, ``info`` and ``recover``: making and inspecting a recording."""

from __future__ import annotations

import json
import signal
import sys
from typing import TYPE_CHECKING, Any

import click

from recorder.cli.options import fail, json_option, root_option
from recorder.cli.root import cli
from recorder.exceptions import ThermcapError

if TYPE_CHECKING:
    from recorder.storage.info import SegmentInfo, SessionInfo


# -- record ---------------------------------------------------------------------------------
@cli.command()
@click.option("--source", default="sim", show_default=True, help="sim, raw:PATH, or raw:- for stdin.")
@click.option("--duration", type=float, default=None,
              help="Seconds to record (default: until the input ends or Ctrl-C).")
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
@click.option("--cue-period", type=float, default=20.0, show_default=True,
              help="Simulator: seconds between radar cues (0: none).")
@click.option("--segment-duration", type=float, default=60.0, show_default=True,
              help="Rotate segments after this many seconds.")
@click.option("--segment-size", type=float, default=4096.0, show_default=True,
              help="Rotate segments after this many MiB.")
@click.option("--compression", type=click.Choice(["auto", "zstd", "lz4", "none"]), default="auto", show_default=True,
              help="Chunk compression; auto: zstd-1 up to 25 Mpixel/s, lz4 above (e.g. 1280x1024@60).")
@click.option("--level", type=int, default=None, help="Compression level (default: zstd 1, lz4 0).")
@click.option("--queue", "queue_frames", type=int, default=120, show_default=True,
              help="Capture queue capacity in frames.")
@click.option("--analysis/--no-analysis", default=True, show_default=True,
              help="Run the hot-spot detector beside recording (fills sidecar targets and contrast grade).")
@click.option("--debug-writer-delay", type=float, default=0.0, hidden=True)
@json_option
def record(source: str, duration: float | None, fps: float, width: int, height: int, sensor_id: str | None,
           root: str, session_id: str | None, pace: bool | None, timestamps: str, seed: int, crossover: bool,
           cue_period: float,
           segment_duration: float, segment_size: float, compression: str, level: int | None, queue_frames: int,
           analysis: bool, debug_writer_delay: float, as_json: bool) -> None:
    """Record a session: frames + ICD sidecars into rotating, crash-safe MCAP segments."""
    from recorder.capture.recorder import Recorder
    from recorder.capture.sources import make_source
    from recorder.storage.segments import SegmentPolicy, auto_compression
    from recorder.storage.writer import Compression

    try:
        is_sim = source == "sim"
        src = make_source(source, width=width, height=height, fps=fps, seed=seed, crossover=crossover,
                          cue_period_s=cue_period, paced=(is_sim if pace is None else pace),
                          duration_s=duration if is_sim else None, sensor_id=sensor_id,
                          timestamps=None if is_sim else timestamps)
        remainder = getattr(src, "file_remainder", 0)
        if remainder:
            click.echo(f"warning: {source[4:]} is not a whole number of {width}x{height} Gray16 frames "
                       f"({remainder} bytes left over); the last frame will be reported as truncated",
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
    from recorder.storage.info import info as get_info

    try:
        data = [get_info(p) for p in paths]
    except ThermcapError as exc:
        fail(str(exc))
    if as_json:
        docs = [d.to_dict() for d in data]
        click.echo(json.dumps(docs[0] if len(docs) == 1 else docs, indent=2))
        return
    for d in data:
        _print_info(d)


def _print_info(d: SegmentInfo | SessionInfo) -> None:
    from rich.console import Console
    from rich.table import Table

    from recorder.storage.info import SessionInfo

    con = Console()
    con.print(f"[bold]{d.session_id or d.path}[/bold]  ({d.path})")
    if isinstance(d, SessionInfo):
        con.print(f"status: {d.status}   sensor: {d.sensor}   segments: {len(d.segments)}"
                  + (f"   unfinished: {', '.join(d.active_segments)}" if d.active_segments else ""))
        if d.hint:
            con.print(f"[yellow]{d.hint}[/yellow]")
    con.print(f"frames: {d.frames}   span: {d.start} .. {d.end} ({d.duration_s:.3f} s)   "
              f"effective fps: {d.effective_fps}")
    if isinstance(d, SessionInfo) and d.time_basis:
        late = d.frames_late or 0
        con.print(f"timestamps: {d.time_basis}   declared fps: {d.declared_fps}   "
                  f"source achieved: {d.achieved_fps} fps   "
                  + (f"[yellow]{late} frames late[/yellow]" if late else "0 frames late"))
    dropped = d.dropped or {}
    con.print(f"dropped: {sum(dropped.values()) if dropped else 0} messages {dropped if dropped else ''}")
    con.print(f"bytes: {d.bytes:,}   chunk compression: {', '.join(d.chunk_compression)}   "
              f"ratio: {d.compression_ratio}")
    t = Table("topic", "messages", "bytes (uncompressed)")
    for topic, v in d.topics.items():
        t.add_row(topic, str(v.messages), f"{v.bytes:,}" if v.bytes is not None else "?")
    con.print(t)
    if isinstance(d, SessionInfo) and d.error:
        con.print(f"[red]error during recording: {d.error}[/red]")


@cli.command()
@click.argument("path", type=click.Path())
@click.option("--keep-original", is_flag=True, help="Keep the .active file after recovery.")
@json_option
def recover(path: str, keep_original: bool, as_json: bool) -> None:
    """Turn interrupted segments (*.mcap.active) into valid, indexed MCAP files."""
    from recorder.storage.recover import recover_path

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


