"""``thermcap ls``: the sessions under a data root, a line each (or JSON for a script)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from thermcap.recorder.cli.options import fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.layout import DataRoot
from thermcap.recorder.storage.manifest_file import read_manifest_file

__all__ = ["describe_session", "ls", "recorded_span"]


def _size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def describe_session(session_dir: Path) -> dict[str, Any]:
    """What ``ls`` says of one session, from its session.json and manifest (no frame is read)."""
    from thermcap.recorder.icd.names import iso_utc
    from thermcap.recorder.storage.layout import SessionLayout
    from thermcap.recorder.storage.lock import session_status

    layout = SessionLayout.of(session_dir)
    try:
        meta = json.loads(layout.session_json.read_text())
    except (OSError, ValueError) as exc:
        from thermcap.recorder.importers.ros2_bag import is_ros2_bag_folder

        if is_ros2_bag_folder(session_dir):  # a bag copied in: not a session until imported
            return {"id": session_dir.name, "state": "ros2-bag (not imported)",
                    "problem": f"a ROS 2 bag, not a session: `thermcap import {session_dir}` makes it one"}
        return {"id": session_dir.name, "state": "unreadable", "problem": f"session.json: {exc}"}
    try:
        manifest = read_manifest_file(session_dir) or {}
    except McapFileError:
        manifest = {"formats": {}, "unreadable": True}
    formats = {f: ("damaged" if e.get("damaged") else "verified" if e.get("verified") else "unverified")
               for f, e in (manifest.get("formats") or {}).items()}
    start, end = recorded_span(meta)
    # the session lock, held only by a live process, says whether "recording" is still true (a
    # recorder killed with SIGKILL leaves session.json saying so, and its lock file behind)
    state, hint = session_status(session_dir, meta.get("status"))
    if state == "interrupted" or (hint and layout.active_segments()):
        state = "interrupted (run `thermcap recover`)"
    return {"id": meta.get("session_id") or session_dir.name, "start": iso_utc(start) if start else meta.get("started"),
            "duration_s": round((end - start) / 1e9, 3) if start and end else None,
            "frames": meta.get("frames_written", meta.get("frames")), "state": state,
            "source_deleted": not layout.segments() and bool(formats), "archived": formats,
            "bytes": _size(session_dir)}


def recorded_span(meta: dict[str, Any]) -> tuple[int | None, int | None]:
    """The session's first and last message times, as ``info`` measures its span, from the
    segments the recorder listed; the process's start and end only where it listed none (a
    session still recording, or one ended by a kill). The process's own times hold its start-up
    (a detector process, a first compile) and would make a 2 s recording look longer."""
    segments = [s for s in meta.get("segments") or [] if isinstance(s, dict) and s.get("start_ns")
                and s.get("end_ns")]
    if segments:
        return min(int(s["start_ns"]) for s in segments), max(int(s["end_ns"]) for s in segments)
    return meta.get("started_ns"), meta.get("ended_ns")


@cli.command("ls")
@root_option
@json_option
def ls(root: str, as_json: bool) -> None:
    """List the sessions under ROOT: id, start, duration, frames, state, archived formats, size."""
    from thermcap.recorder.storage.reader import list_sessions

    if not DataRoot.of(root).sessions.is_dir():
        fail(f"{root}: not a thermcap data root (no sessions/ folder); pass --root or set THERMCAP_ROOT")
    rows = [describe_session(s) for s in list_sessions(root)]
    if as_json:
        click.echo(json.dumps({"root": str(root), "sessions": rows}, indent=2))
        return
    if not rows:
        click.echo(f"{root}: no sessions")
        return
    click.echo(f"{'id':24} {'start':24} {'duration':>9} {'frames':>8} {'state':11} {'bytes':>14}  archived")
    for r in rows:
        dur = f"{r['duration_s']:.1f} s" if r.get("duration_s") is not None else "-"
        arch = ", ".join(f"{f}" + ("" if s == "verified" else f" ({s})") for f, s in r.get("archived", {}).items())
        click.echo(f"{r['id'][:24]:24} {(r.get('start') or '-')[:24]:24} {dur:>9} {r.get('frames') or 0:>8} "
                   f"{r['state'].split(' (')[0][:11]:11} {r.get('bytes', 0):>14,}  {arch or '-'}")
    if any(r["state"].startswith("interrupted") for r in rows):
        click.echo("interrupted: the recorder stopped without finishing; `thermcap recover SESSION` finishes it")
    for r in rows:
        if r.get("problem"):
            click.echo(f"{r['id']}: {r['problem']}")
