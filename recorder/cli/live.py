"""``thermcap play``: review a recorded or archived session in Foxglove as if it were live."""

from __future__ import annotations

import json
import signal
import threading

import click

from thermcap.recorder.cli.options import PORT, Number, fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError


@cli.command()
@click.argument("session")
@root_option
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to serve on: a loopback one, since the view has no token (reach it from elsewhere "
                   "through an SSH tunnel).")
@click.option("--port", type=PORT, default=8765, show_default=True, help="Port (0: any free port).")
@click.option("--rate", type=Number(minimum=0, above=True, maximum=1000), default=1.0, show_default=True,
              help="Playback speed (2: twice as fast).")
@click.option("--loop", is_flag=True, help="Start again at the end, until Ctrl-C.")
@click.option("--start", "start_s", type=Number(minimum=0, unit="s"), default=0.0, show_default=True,
              help="Seconds into the session to start from.")
@click.option("--fps", "max_fps", type=Number(minimum=0, maximum=1000, unit="fps"), default=0.0, show_default=True,
              help="Most frames/s per camera (0: every frame).")
@click.option("--width", "max_width", type=Number(minimum=0, maximum=16384, integer=True), default=0, show_default=True,
              help="Subsample the picture to at most this width (0: full resolution).")
@click.option("--duration", "duration_s", type=Number(minimum=0, above=True, unit="s"), default=None,
              help="Stop after this many seconds.")
@click.option("--wait-for-viewer", type=Number(minimum=0, maximum=86400, unit="s"), default=0.0, show_default=True,
              help="Wait up to this many seconds for a viewer to subscribe before the first frame.")
@json_option
def play(session: str, root: str, host: str, port: int, rate: float, loop: bool, start_s: float, max_fps: float,
         max_width: int, duration_s: float | None, wait_for_viewer: float, as_json: bool) -> None:
    """Replay SESSION (a folder, or an id under ROOT/sessions) over the Foxglove WebSocket
    protocol: images, sidecars, annotations, temperatures and events, at the recorded pace."""
    from thermcap.recorder.live.publisher import LiveOptions, LivePublisher, check_live_host
    from thermcap.recorder.live.replay import replay_session
    from thermcap.recorder.storage.reader import resolve_session

    try:
        check_live_host(host, port, "--host")
    except ValueError as exc:
        fail(str(exc))
    try:
        session_dir = resolve_session(session, root)
    except ThermcapError as exc:
        fail(str(exc))
    try:
        # a replay can wait for nothing, so a viewer gets a deep buffer (the SDK's default) before
        # its oldest messages are dropped
        publisher = LivePublisher(LiveOptions(host=host, port=port, max_width=max_width, name="thermcap play",
                                              backlog=1024))
    except Exception as exc:  # the SDK's own error for a busy port
        fail(f"cannot serve on {host}:{port}: {exc}")
    click.echo(json.dumps({"url": publisher.url}) if as_json else
               f"playing {session_dir.name} on {publisher.url}  (Foxglove: Open connection -> Foxglove WebSocket)")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        result = replay_session(session_dir, publisher, rate=rate, loop=loop, start_s=start_s, max_fps=max_fps,
                                stop=stop, duration_s=duration_s, wait_for_viewer_s=wait_for_viewer)
        if not stop.is_set():
            stop.wait(1.0)  # the server sends on its own threads: let viewers receive the last messages
    except ThermcapError as exc:
        fail(str(exc))
    finally:
        publisher.close()
    if as_json:
        click.echo(json.dumps(result.to_dict()))
    else:
        click.echo(f"played {result.frames} frames and {result.events} events in {result.wall_s} s "
                   f"({result.loops} pass{'es' if result.loops != 1 else ''})")
