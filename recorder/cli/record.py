"""``thermcap record``, ``info`` and ``recover``: making and inspecting a recording."""

from __future__ import annotations

import dataclasses
import json
import signal
import sys
from typing import TYPE_CHECKING, Any

import click

from thermcap.recorder import settings
from thermcap.recorder.cli.listing import recorded_span
from thermcap.recorder.cli.options import PORT, Number, fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError

if TYPE_CHECKING:
    from thermcap.recorder.storage.info import SegmentInfo, SessionInfo


# -- record ---------------------------------------------------------------------------------
MAX_FRAME_PIXELS = 8192 * 8192
RING_FRAMES_AT_LEAST = 16  # the smallest --max-disk, in raw frames
EXIT_DROPPED = 3  # the recording finished, but frames were dropped: not the same as a failure (1)
# the recording kept every frame it was given, but the source lost some before it (a camera gone
# for a while, incomplete buffers, frames the camera numbered that never came)
EXIT_SOURCE_LOSS = 4

@cli.command()
@click.option("--source", "sources", multiple=True, default=["sim"], show_default=True, metavar="[NAME=]SOURCE",
              help="sim, raw:PATH (raw:- for stdin), exec:COMMAND (a command writing raw Gray16, restarted when "
                   "it ends) or gige:CAMERA (GigE Vision through Aravis; GenICam features as Name=value keys); "
                   "repeat with names for several cameras in one session "
                   "(left=sim --source right=raw:/dev/stdin,width=320,height=256,fps=30).")
@click.option("--duration", type=Number(minimum=0, above=True, unit="s"), default=None,
              help="Seconds to record (default: until the input ends or Ctrl-C).")
@click.option("--fps", type=Number(minimum=0, above=True, maximum=10_000, unit="fps"), default=60.0, show_default=True)
@click.option("--width", type=Number(minimum=1, maximum=16384, integer=True, unit="pixels"), default=640,
              show_default=True)
@click.option("--height", type=Number(minimum=1, maximum=16384, integer=True, unit="pixels"), default=512,
              show_default=True)
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
@click.option("--cue-period", type=Number(minimum=0, unit="s"), default=20.0, show_default=True,
              help="Simulator: seconds between radar cues (0: none).")
@click.option("--segment-duration", type=Number(minimum=0, unit="s"), default=60.0, show_default=True,
              help="Rotate segments after this many seconds (with --ring --max-disk and not given: at most a "
                   "tenth of the budget).")
@click.option("--settle-timeout", type=Number(minimum=0, above=True, maximum=86_400, unit="s"), default=60.0,
              show_default=True,
              help="At the end, wait this long for the disk to confirm the last segments (fsync); past it the "
                   "recorder exits 1 naming them, and `thermcap recover` finishes them once the disk answers.")
@click.option("--segment-size", type=Number(minimum=0, unit="MiB"), default=4096.0, show_default=True,
              help="Rotate segments after this many MiB.")
@click.option("--compression", type=click.Choice(["auto", "zstd", "lz4", "none"]), default="auto", show_default=True,
              help="Chunk compression; auto: zstd-1 up to 25 Mpixel/s, lz4 above (e.g. 1280x1024@60).")
@click.option("--level", type=Number(minimum=0, maximum=22, integer=True), default=None,
              help="Compression level (default: zstd 1, lz4 0).")
@click.option("--queue", "queue_frames", type=Number(minimum=1, maximum=100_000, integer=True, unit="frames"),
              default=120, show_default=True,
              help="Capture queue capacity in frames.")
@click.option("--analysis/--no-analysis", default=True, show_default=True,
              help="Run the hot-spot detector beside recording (fills sidecar targets and contrast grade).")
@click.option("--ring", is_flag=True,
              help="Always on: record until stopped, deleting the oldest unprotected segments to stay within "
                   "--max-disk and --min-free (logged to ROOT/eviction.log).")
@click.option("--max-disk", default=None, metavar="SIZE", help="With --ring: the most the data root may hold (20G).")
@click.option("--min-free", default=None, metavar="SIZE|PCT",
              help="With --ring: keep this much free on the data root's disk (5G or 10%).")
@click.option("--evict-only-synced", is_flag=True,
              help="With --ring: delete only segments the cloud confirmed (thermcap sync receipts), whatever the "
                   "pressure.")
@click.option("--max-protected", default=None, metavar="SIZE",
              help="With --ring: the most event windows may hold (default: half of --max-disk); past it the oldest "
                   "window goes first, logged and shown on health.")
@click.option("--keep-events", is_flag=True,
              help="With --ring: never let an event window go; when only protected segments are left, new frames "
                   "are dropped (or a file or pipe waits) instead.")
@click.option("--pre", "pre_s", type=Number(minimum=0, maximum=86400, unit="s"), default=30.0, show_default=True,
              help="Seconds kept before a trigger or mark (with --ring --max-disk and not given: fitted to the "
                   "budget).")
@click.option("--post", "post_s", type=Number(minimum=0, maximum=86400, unit="s"), default=30.0, show_default=True,
              help="Seconds kept after a trigger or mark (fitted to the budget like --pre).")
@click.option("--trigger-hot", type=Number(minimum=-273.15, maximum=5000, unit="°C"), default=None, metavar="DEGC",
              help="Trigger when a target at or above this temperature appears.")
@click.option("--trigger-target-count", is_flag=True, help="Trigger when the number of targets changes.")
@click.option("--control", "control", is_flag=True,
              help="Serve the control endpoint (thermcap ctl; /status, /metrics, /healthz) on 127.0.0.1.")
@click.option("--control-port", type=PORT, default=0, show_default=True, help="Its port (0: any free port).")
@click.option("--control-token", envvar=settings.CONTROL_TOKEN.name, default=None, show_envvar=True,
              help="Bearer token every control route but /healthz requires (set it in the environment).")
@click.option("--control-insecure", is_flag=True,
              help="Run the control endpoint without a token (any local user could pause the recording).")
@click.option("--live", is_flag=True, help="Serve a live view for Foxglove (Open connection: ws://HOST:PORT).")
@click.option("--live-host", default="127.0.0.1", show_default=True,
              help="Address of the live view: a loopback one, since it has no token (reach it from the vehicle "
                   "network through an SSH tunnel).")
@click.option("--live-port", type=PORT, default=8765, show_default=True)
@click.option("--live-fps", type=Number(minimum=0, above=True, maximum=1000, unit="fps"), default=10.0,
              show_default=True, help="Most frames/s per camera it sends.")
@click.option("--live-width", type=Number(minimum=0, maximum=16384, integer=True), default=0, show_default=True,
              help="Subsample the live picture to at most this width (0: full resolution).")
@click.option("--debug-writer-delay", type=float, default=0.0, hidden=True)
@json_option
def record(sources: tuple[str, ...], duration: float | None, fps: float, width: int, height: int, sensor_id: str | None,
           root: str, session_id: str | None, pace: bool | None, timestamps: str, seed: int, crossover: bool,
           cue_period: float,
           segment_duration: float, settle_timeout: float,
           segment_size: float, compression: str, level: int | None, queue_frames: int,
           analysis: bool, ring: bool, max_disk: str | None, min_free: str | None, evict_only_synced: bool,
           max_protected: str | None, keep_events: bool,
           pre_s: float, post_s: float,
           trigger_hot: float | None, trigger_target_count: bool, control: bool, control_port: int,
           control_token: str | None, control_insecure: bool, live: bool, live_host: str, live_port: int,
           live_fps: float, live_width: int, debug_writer_delay: float, as_json: bool) -> None:
    """Record a session: frames + ICD sidecars into rotating, crash-safe MCAP segments.

    With --ring it records until stopped within a disk budget; triggers (--trigger-*, the contrast
    grade under 0.3, radar cues, `thermcap ctl mark`, SIGUSR1) protect --pre/--post seconds around them.
    """
    from thermcap.recorder.capture.control import ControlServer
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources import make_source
    from thermcap.recorder.capture.sources.registry import CameraSettings, settings_from
    from thermcap.recorder.capture.sources.spec import parse_source_spec
    from thermcap.recorder.capture.triggers import TriggerPolicy
    from thermcap.recorder.storage.layout import check_session_name
    from thermcap.recorder.storage.ring import RingPolicy
    from thermcap.recorder.storage.segments import SegmentPolicy, auto_compression
    from thermcap.recorder.storage.writer import Compression, check_level

    live_branch = None
    try:
        if session_id is not None:
            check_session_name(session_id)
        if width * height > MAX_FRAME_PIXELS:
            raise click.BadParameter(f"--width {width} --height {height}: a frame of {width * height:,} pixels; "
                                     f"at most {MAX_FRAME_PIXELS:,} (8192x8192)")
        specs = [parse_source_spec(s) for s in sources]
        if len(specs) > 1:
            specs = [sp if sp.name else dataclasses.replace(sp, name=f"cam{i}") for i, sp in enumerate(specs)]
            names = [sp.name for sp in specs]
            if len(set(names)) != len(names):
                raise click.BadParameter(f"camera names must differ: {', '.join(str(n) for n in names)}")
        srcs = {}
        pixel_rate = 0.0
        flags = CameraSettings(width=width, height=height, fps=fps, sensor_id=sensor_id, pace=pace,
                               timestamps=timestamps, seed=seed, crossover=crossover, cue_period_s=cue_period,
                               duration_s=duration)
        for sp in specs:
            settings = settings_from(sp.options, flags)
            src = make_source(sp, settings)
            remainder = getattr(src, "file_remainder", 0)
            if remainder:
                click.echo(f"warning: {sp.target} is not a whole number of {settings.width}x{settings.height} "
                           f"Gray16 frames ({remainder} bytes left over); the last frame will be reported as "
                           f"truncated", err=True)
            srcs[sp.name] = src
            pixel_rate += settings.width * settings.height * settings.fps
        # the simulator ends itself at --duration (exactly duration x fps frames); others are stopped
        ends_itself = all(sp.source_kind.counts_duration for sp in specs)
        if ring and max_disk:
            # the defaults (60 s segments, 30 s either side) shrunk to what the budget holds, where
            # they were not given: the page's 200M could not keep one window or one segment
            from click.core import ParameterSource

            from thermcap.recorder.sizes import parse_size
            from thermcap.recorder.storage.ring import fit_to_budget

            ctx = click.get_current_context()
            defaulted = {n for n in ("segment_duration", "pre_s", "post_s")
                         if ctx.get_parameter_source(n) == ParameterSource.DEFAULT}
            if defaulted:
                disk = parse_size(max_disk)
                fitted = fit_to_budget(disk, parse_size(max_protected) if max_protected else disk // 2,
                                       pixel_rate * 2, segment_duration or 60.0, 30.0)
                segment_duration = fitted.segment_s if "segment_duration" in defaulted else segment_duration
                pre_s = fitted.pre_s if "pre_s" in defaulted else pre_s
                post_s = fitted.post_s if "post_s" in defaulted else post_s
                if not as_json and (segment_duration, pre_s, post_s) != (60.0, 30.0, 30.0):
                    click.echo(f"ring: {segment_duration:g} s segments, events keep {pre_s:g} s before and "
                               f"{post_s:g} s after: what --max-disk {max_disk} holds at "
                               f"{pixel_rate * 2 / 1e6:,.0f} MB/s uncompressed (set --segment-duration, --pre, "
                               f"--post to choose)", err=True)
        if compression == "auto":
            comp, default_level = auto_compression(int(pixel_rate), 1, 1.0)
        else:
            comp, default_level = Compression(compression), (1 if compression == "zstd" else 0)
        if level is not None:
            check_level(comp, level)
        policy = SegmentPolicy(max_duration_s=segment_duration or None,
                               max_bytes=int(segment_size * 1024 * 1024) if segment_size else None,
                               compression=comp, compression_level=default_level if level is None else level,
                               settle_timeout_s=settle_timeout)
        if (max_disk or min_free or max_protected or keep_events) and not ring:
            raise click.BadParameter("--max-disk, --min-free, --max-protected and --keep-events need --ring")
        ring_policy = RingPolicy.parse(max_disk, min_free, pre_s, post_s, evict_only_synced, max_protected,
                                       keep_events) if ring else None
        if ring_policy is not None and ring_policy.max_disk is not None \
                and ring_policy.max_disk < RING_FRAMES_AT_LEAST * width * height * 2:
            raise click.BadParameter(f"--max-disk {max_disk}: smaller than {RING_FRAMES_AT_LEAST} raw "
                                     f"{width}x{height} frames; a ring must hold its segments")
        if ring and ring_policy is not None and ring_policy.max_disk is None and ring_policy.min_free is None \
                and ring_policy.min_free_percent is None:
            raise click.BadParameter("--ring needs --max-disk and/or --min-free")
        if control and not control_token and not control_insecure:
            raise click.BadParameter("--control needs a token: set THERMCAP_CONTROL_TOKEN (or --control-token), "
                                     "or pass --control-insecure to run it open to every local user")
        if live:
            from thermcap.recorder.live.publisher import check_live_host

            check_live_host(live_host, live_port, "--live-host")
            from thermcap.recorder.live.branch import LiveBranch
            from thermcap.recorder.live.publisher import LiveOptions

            try:
                live_branch = LiveBranch(LiveOptions(host=live_host, port=live_port, max_fps=live_fps,
                                                     max_width=live_width))
            except Exception as exc:  # the SDK raises its own error types for a busy port
                raise ValueError(f"live view on {live_host}:{live_port}: {exc}") from None
        single = srcs.get(None)
        rec = Recorder(single if single is not None else {str(k): v for k, v in srcs.items()}, root,
                       session_id=session_id, policy=policy,
                       queue_frames=queue_frames,
                       writer_delay_s=debug_writer_delay, analysis=analysis, ring=ring_policy,
                       triggers=TriggerPolicy(hot_spot_c=trigger_hot, target_count=trigger_target_count),
                       live=live_branch)
    except click.BadParameter as exc:
        fail(str(exc.message))
    except ThermcapError as exc:
        fail(str(exc))
    except (ValueError, OSError) as exc:
        fail(str(exc))

    if not as_json:
        click.echo(f"session {rec.session_id} -> {rec.session_dir}")
        if live_branch is not None:
            click.echo(f"live view: {live_branch.url}  (Foxglove: Open connection -> Foxglove WebSocket)")
    signal.signal(signal.SIGTERM, lambda *_: rec.stop())
    signal.signal(signal.SIGUSR1, lambda *_: rec.mark("SIGUSR1", reason="signal"))
    server = None
    if control:
        try:
            server = ControlServer(rec, port=control_port, token=control_token, insecure=control_insecure)
        except OSError as exc:
            fail(f"control endpoint on 127.0.0.1:{control_port}: {exc.strerror or exc}")
    from thermcap.recorder.cli.progress import verbosity

    progress = None if as_json or not sys.stderr.isatty() or verbosity() < 0 else _progress_line()
    try:
        if server is not None:
            server.start()
            if not as_json:
                click.echo(f"control: {server.url}  (thermcap ctl status --root {root})")
        result = rec.run(duration_s=None if ends_itself else duration, progress=progress)
    except ThermcapError as exc:
        fail(str(exc))
    finally:
        if server is not None:
            server.stop()
        if live_branch is not None:
            live_branch.close()
    if progress is not None:
        click.echo("", err=True)
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
    else:
        for p in result.recovered:
            click.echo(f"recovered leftover segment {p}")
        lat = result.write_latency_ms
        unconfirmed = (f"{result.frames_unconfirmed} unconfirmed by the disk (complete in .active files), "
                       if result.frames_unconfirmed else "")
        # one rate, the one info and the stats give: frames over their own span (the command's
        # wall time, start-up included, is said apart)
        first, last = recorded_span({"segments": result.segments})  # what ls shows
        span_s = (last - first) / 1e9 if first and last else 0.0
        rate = f"{(result.frames_written - 1) / span_s:.1f} fps over {span_s:.1f} s, " if span_s > 0 else ""
        click.echo(f"frames: {result.frames_captured} captured, {result.frames_written} written, {unconfirmed}"
                   f"{result.frames_dropped} dropped  ({rate}{result.wall_s:.1f} s in all)")
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
            for line in analysis_notes(result.analysis_runner or {}, result.wall_s,
                                       result.frames_written - result.analysis_skipped):
                click.echo(line)
        for name, cam in result.cameras.items():
            click.echo(f"camera {name}: {cam['frames_captured']} captured, {cam['frames_written']} written, "
                       f"{cam['frames_dropped']} dropped" + (f"; {cam['error']}" if cam["error"] else ""))
        if result.live is not None:
            lv = result.live
            click.echo(f"live view: {lv['published']} frames sent, {lv['skipped_for_rate']} above --live-fps, "
                       f"{lv['dropped']} dropped by the view (never by the recording)")
    if result.error:
        fail(result.error)
    if result.frames_dropped:  # exit 0 means nothing recorded was lost
        fail(f"{result.frames_dropped} of {result.frames_captured} frames were dropped "
             f"({'; '.join(result.problems[:2])}); the session keeps the {result.frames_written} written",
             code=EXIT_DROPPED)
    from thermcap.recorder.capture.sources.health import source_losses

    losses = source_losses(result.source_health)
    if losses:
        fail(f"the source lost frames before the recorder: {'; '.join(losses)}; the session keeps the "
             f"{result.frames_written} it was given", code=EXIT_SOURCE_LOSS)


# -- ctl ------------------------------------------------------------------------------------
@cli.command()
@click.argument("action", type=click.Choice(["status", "split", "pause", "resume", "mark", "snapshot", "metrics",
                                             "health"]))
@click.option("--note", default="", help="mark/snapshot: what happened.")
@root_option
@click.option("--session", "session_id", default=None, help="Which recorder, when several run under ROOT.")
@click.option("--url", default=None, help="The control endpoint (default: found under ROOT/run/).")
@click.option("--token", envvar=settings.CONTROL_TOKEN.name, default=None, show_envvar=True,
              help="The recorder's control token.")
@json_option
def ctl(action: str, note: str, root: str, session_id: str | None, url: str | None, token: str | None,
        as_json: bool) -> None:
    """Control a running recorder: status, split (a new segment, no frame lost), pause/resume (a
    recorded gap), mark/snapshot (an event whose window is kept), metrics, health."""
    import urllib.error
    import urllib.parse
    import urllib.request

    from thermcap.recorder.capture.control import find_control
    from thermcap.recorder.loopback import is_loopback

    try:
        base = url or find_control(root, session_id)["url"]
    except ThermcapError as exc:
        fail(str(exc))
    host = urllib.parse.urlsplit(base).hostname or ""
    if token and url is None and not is_loopback(host):
        # the address came from a file anyone who can write ROOT/run/ may have written
        fail(f"{base}: the recorder's address file names a host off this machine; the token is sent only to "
             f"127.0.0.1 (name the endpoint with --url to send it there)")
    route = {"health": "/healthz"}.get(action, f"/{action}")
    method = "POST" if action in ("split", "pause", "resume", "mark", "snapshot") else "GET"
    body = json.dumps({"note": note}).encode() if method == "POST" else None
    req = urllib.request.Request(base + route, data=body, method=method,
                                 headers={"Content-Type": "application/json",
                                          **({"Authorization": f"Bearer {token}"} if token else {})})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            code, text = r.status, r.read().decode()
    except urllib.error.HTTPError as exc:
        code, text = exc.code, exc.read().decode()
    except OSError as exc:
        fail(f"{base}: {exc}")
    if code >= 400 and action != "health":
        try:
            said = json.loads(text).get("error") or text
        except (ValueError, AttributeError):
            said = text
        fail(f"{base}{route}: {code}: {said}")
    if action == "metrics":
        click.echo(text, nl=False)
    elif action in ("mark", "snapshot") and not as_json:
        click.echo(mark_text(json.loads(text)))
    elif as_json or action != "status":
        click.echo(text)
    else:
        click.echo(status_text(json.loads(text)))
    if code >= 400:
        sys.exit(1)


def mark_text(answer: dict[str, Any]) -> str:
    """``ctl mark``'s answer for a person: what the ring will keep of the window."""
    keeps = answer.get("keeps")
    line = f"marked{': ' + answer['note'] if answer.get('note') else ''}"
    if not keeps:
        return line
    window = f"{keeps['pre_s']:g} s before and {keeps['post_s']:g} s after"
    if keeps["kept"] == "not whole":
        return f"{line}\nwarning: the window ({window}) will not be kept whole: {keeps['why']}"
    return f"{line}; its window ({window}) is kept: {keeps['kept']}"


#: The detector's share worth a line: a tenth of the recording's time, in CPU or in waiting
_WORTH_SAYING = 0.1


def analysis_notes(runner: dict[str, Any], wall_s: float, analysed: int) -> list[str]:
    """Why analysis slowed a recording, for a person: the frames where a detection cap bit (the
    view held more candidates than targets can: noise or texture), and, for a source that waits
    for the detector (a file, a pipe: every frame is analysed), what the detector cost beside
    the recording and how long the recording waited for it. On two cores the detector's CPU is
    what slows a file most, more than the waits: both processes share the cores."""
    out = []
    if capped := runner.get("capped"):
        rules = ", ".join(f"{rule} {n}" for rule, n in capped.items())
        out.append(f"analysis: a cap bit on {sum(capped.values())} frames ({rules}): the view held more "
                   "candidates than targets can (noise or texture); each frame names it in "
                   "thermal_analysis.detection_capped")
    waited = float(runner.get("waited_for_detector_s") or 0.0)  # only a source that waits waits
    cpu = float(runner.get("cpu_s") or 0.0)
    if waited > 0 and max(waited, cpu) >= _WORTH_SAYING * wall_s:
        per_frame = f" ({1e3 * cpu / analysed:.2f} ms a frame)" if analysed else ""
        out.append(f"analysis: the detector took {cpu:.1f} s of CPU{per_frame} beside the recording, which "
                   f"waited {waited:.1f} s of its {wall_s:.1f} s for it: a file is analysed frame by frame, on "
                   "the same cores. --no-analysis records it without; `thermcap analyze SESSION` runs the "
                   "detector afterwards")
    return out


def status_text(st: dict[str, Any]) -> str:
    """``ctl status`` for a person: the recorder's state, its counts, and whatever needs a look."""
    out = [f"{st['session_id']}: {'paused' if st['paused'] else 'recording'}, "
           f"{'healthy' if st['healthy'] else 'UNHEALTHY: ' + '; '.join(st['problems'])}"]
    out.append(f"frames: {st['frames_captured']} captured, {st['frames_written']} written, "
               f"{sum(c.get('frames_dropped', 0) for c in st['cameras'].values())} frames dropped, "
               f"{st['frames_paused']} paused; "
               f"queue {st['queue_depth']}/{st['queue_capacity']}; segment {st['segment']}")
    if settling := st.get("segments_settling"):
        out.append(f"disk: {len(settling)} closed segments waiting for fsync, the oldest "
                   f"{settling[0]['name']} for {settling[0]['waiting_s']:.1f} s")
    if len(st.get("cameras") or {}) > 1:
        for name, c in st["cameras"].items():
            out.append(f"  camera {name}: {c['frames_written']} written, {c['frames_dropped']} dropped"
                       + (f"; {c['error']}" if c["error"] else ""))
    if st.get("live"):
        lv = st["live"]
        out.append(f"live view: {lv['url']}, {lv['viewers']} viewers, {lv['published']} frames sent, "
                   f"{lv['dropped']} dropped by the view")
    if st.get("ring"):
        r = st["ring"]
        out.append(f"ring: {r['evicted_segments']} segments ({r['evicted_bytes']:,} bytes) evicted, "
                   f"{r['protected_windows']} windows protected" + (f"; BLOCKED: {r['blocked_reason']}"
                                                                    if r["blocked"] else ""))
    return "\n".join(out)


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
    from thermcap.recorder.storage.info import info as get_info

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
    from rich import box
    from rich.console import Console
    from rich.table import Table

    from thermcap.recorder.storage.info import SessionInfo

    plain = not sys.stdout.isatty()  # a pipe or a file: no boxes, no wrapping
    con = Console(width=10_000 if plain else None, soft_wrap=plain)
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
    if isinstance(d, SessionInfo) and d.source:
        from thermcap.recorder.capture.sources.health import source_line, source_losses

        line = source_line(d.source, d.source_health)
        con.print(f"[yellow]{line}[/yellow]" if source_losses(d.source_health) else line)
    if isinstance(d, SessionInfo) and d.cameras:
        cams = Table("camera", "sensor", "frames", "captured", "dropped", "effective fps", "error",
                     box=None if plain else box.HEAVY_HEAD)
        for name, c in d.cameras.items():
            cams.add_row(name, c.sensor or "?", str(c.frames), str(c.frames_captured), str(c.frames_dropped),
                         str(c.effective_fps), c.error or "")
        con.print(cams)
    if isinstance(d, SessionInfo) and d.gaps:
        con.print(f"gaps: {len(d.gaps)} ({sum(g['seconds'] for g in d.gaps):.3f} s without frames): "
                  + ", ".join(f"{g['start']} ({g['seconds']:.3f} s)" for g in d.gaps[:5])
                  + (" ..." if len(d.gaps) > 5 else ""))
    if isinstance(d, SessionInfo) and d.pauses:
        con.print(f"paused {len(d.pauses)} times, {d.frames_paused} frames not recorded: "
                  + ", ".join(f"{(b - a) / 1e9:.1f} s" if a is not None and b is not None else "to the end"
                              for a, b in d.pauses))
    if isinstance(d, SessionInfo) and d.ring:
        con.print(f"ring: {d.evicted_segments} segments evicted (ROOT/eviction.log says when and why)")
    con.print(f"bytes: {d.bytes:,}   chunk compression: {', '.join(d.chunk_compression)}   "
              f"ratio: {d.compression_ratio}")
    t = Table("topic", "messages", "bytes (uncompressed)", box=None if plain else box.HEAVY_HEAD)
    for topic, v in d.topics.items():
        t.add_row(topic, str(v.messages), f"{v.bytes:,}" if v.bytes is not None else "?")
    con.print(t)
    if isinstance(d, SessionInfo) and d.error:
        con.print(f"[red]error during recording: {d.error}[/red]")


@cli.command("split-cameras")
@click.argument("session")
@root_option
@click.option("--delete-source", is_flag=True,
              help="Delete the session's own segments once every camera's copy compared equal.")
@json_option
def split_cameras_cmd(session: str, root: str, delete_source: bool, as_json: bool) -> None:
    """One single-camera session per camera of SESSION (ROOT/sessions/<id>.<camera>), bit-exact:
    what the archiver, the index and the API take like any other session."""
    from thermcap.recorder.storage.reader import resolve_session
    from thermcap.recorder.storage.split import split_cameras

    try:
        res = split_cameras(resolve_session(session, root), delete_source=delete_source)
    except ThermcapError as exc:
        fail(str(exc))
    if as_json:
        click.echo(json.dumps(res.to_dict(), indent=2))
        return
    for cam, path in res.cameras.items():
        click.echo(f"{cam}: {path} ({res.frames[cam]} frames{', made earlier' if cam in res.already else ''})")
    if res.source_deleted:
        click.echo("the session's own segments were deleted: every copy compared equal, frame by frame")


@cli.command()
@click.argument("path", type=click.Path())
@click.option("--keep-original", is_flag=True,
              help="Keep the original beside the result (NNNN.mcap.active, or NNNN.mcap.orig for a closed segment).")
@json_option
def recover(path: str, keep_original: bool, as_json: bool) -> None:
    """Turn interrupted segments (*.mcap.active) into valid, indexed MCAP files, and repair closed
    segments cut short in place (the same name, so the session still counts them).

    PATH is a segment, a session folder or a data root. session.json is updated to what the
    segments now hold, with what each repair kept and discarded."""
    from thermcap.recorder.storage.recover import recover_path

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


