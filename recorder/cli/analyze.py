"""``thermcap analyze``: the detector over recorded sessions, offline."""

from __future__ import annotations

import json

import click

from thermcap.recorder.cli.options import Number, fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError


@cli.command()
@click.argument("sessions", nargs=-1, required=True)
@root_option
@click.option("--threshold", type=Number(minimum=0, above=True, unit="K"), default=5.0, show_default=True,
              help="K above the local background.")
@click.option("--min-area", type=Number(minimum=1, integer=True, unit="pixels"), default=4, show_default=True,
              help="Smallest target, in pixels.")
@click.option("--min-crossover", type=Number(minimum=0, unit="s"), default=1.0, show_default=True,
              help="Seconds of grade < 0.3 that make a thermal_crossover event.")
@json_option
def analyze(sessions: tuple[str, ...], root: str, threshold: float, min_area: int, min_crossover: float,
            as_json: bool) -> None:
    """(Re)run hot-spot detection on sessions: analysis.jsonl and events.json beside the segments."""
    from thermcap.recorder.analysis.offline import analyze_session
    from thermcap.recorder.storage.reader import resolve_session

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


