"""The ``thermcap`` command: the root group, composed from the three rooms' subcommands.

Each room keeps its commands beside its code (``recorder.cli``, ``archive.cli``, ``api.cli``);
this module, above all three, imports them directly, so the import graph shows who depends on
whom. Entry points remain for third-party plugins only: a command of yours in the group
``thermcap.commands``, a benchmark in ``thermcap.bench``; thermcap's own benchmarks are in
``thermcap.benches``.
"""

from __future__ import annotations

from typing import Any

import click

from thermcap.api import cli as api_cli
from thermcap.archive import cli as archive_cli
from thermcap.benches.cli import bench as bench_commands
from thermcap.recorder import settings
from thermcap.recorder.cli import cli as recorder_commands
from thermcap.recorder.cli.options import fail, root_option
from thermcap.recorder.exceptions import ThermcapError

__all__ = ["bench", "cli", "main"]

HELP = {"help_option_names": ["-h", "--help"]}


class _Group(click.Group):
    """A group that also offers the commands third-party packages registered as entry points,
    looked up only when a name is not ours or the whole list is asked for (reading the installed
    distributions' metadata costs tens of milliseconds a start)."""

    def __init__(self, *args: Any, entry_point_group: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._ep_group = entry_point_group
        self._loaded = False

    def _load(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        from importlib.metadata import entry_points

        for ep in entry_points(group=self._ep_group):
            if ep.name not in self.commands:
                self.add_command(ep.load(), ep.name)

    def list_commands(self, ctx: click.Context) -> list[str]:
        self._load()
        return super().list_commands(ctx)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in self.commands:
            self._load()
        return super().get_command(ctx, name)


@click.group(cls=_Group, entry_point_group="thermcap.commands", context_settings=HELP)
@click.version_option(package_name="thermcap", prog_name="thermcap")
@click.option("--config", "config", envvar=settings.CONFIG.name, show_envvar=True, default=None, metavar="FILE",
              type=click.Path(dir_okay=False),
              help="A TOML file of defaults, a table per command ([record], [serve], ...); flags still win.")
@click.option("-q", "--quiet", is_flag=True, help="Only errors and the results a script reads; no progress.")
@click.option("-v", "--verbose", count=True, help="More detail (log messages at INFO; -vv: DEBUG).")
@click.pass_context
def cli(ctx: click.Context, config: str | None, quiet: bool, verbose: int) -> None:
    """Record, archive and serve radiometric thermal camera data (Gray16 on MCAP)."""
    import logging

    ctx.obj = {"verbosity": -1 if quiet else verbose}
    if verbose:
        logging.basicConfig(level=logging.DEBUG if verbose > 1 else logging.INFO,
                            format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if config:
        from thermcap.recorder.cli.config import load_config

        assert isinstance(ctx.command, click.Group)
        ctx.default_map = load_config(config, ctx.command, ctx)


@cli.group(cls=_Group, entry_point_group="thermcap.bench", context_settings=HELP)
def bench() -> None:
    """Benchmarks: each prints ratios against a baseline measured in the same run."""


for _name, _command in recorder_commands.commands.items():
    cli.add_command(_command, _name)
for _command in (archive_cli.archive, archive_cli.verify, archive_cli.audit, archive_cli.scrub,
                 archive_cli.sync_confirm, api_cli.serve, api_cli.index, api_cli.upload, api_cli.worker,
                 api_cli.gc, api_cli.watch, api_cli.jobs):
    cli.add_command(_command)
for _name, _command in bench_commands.commands.items():
    bench.add_command(_command, _name)


@cli.command("cut")
@click.argument("session")
@root_option
@click.option("--start", default=None, metavar="TIME",
              help="From this time: RFC 3339, or seconds from the first frame.")
@click.option("--end", default=None, metavar="TIME", help="Until this time (not included); as --start.")
@click.option("--topics", default=None, metavar="T1,T2", help="Only these topics (default: all).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="The MCAP file to write.")
@click.option("--json", "as_json", is_flag=True, help="One JSON document.")
def cut(session: str, root: str, start: str | None, end: str | None, topics: str | None, out: str,
        as_json: bool) -> None:
    """Part of SESSION, by time and topic, as one MCAP file (the source's chunks copied where they
    lie inside; from the archive once the source is deleted)."""
    import json
    from pathlib import Path

    from thermcap.cut import cut_session
    from thermcap.recorder.exceptions import McapFileError
    from thermcap.recorder.storage.reader import resolve_session

    try:
        d = resolve_session(session, root)
        res = cut_session(Path(d), Path(d).parent.parent, Path(out), start, end,
                          [t for t in (topics or "").split(",") if t] or None)
    except (ValueError, FileExistsError) as exc:
        fail(str(exc))
    except McapFileError as exc:
        fail(f"{exc}; nothing was written (`thermcap scrub` and `thermcap recover` say what the session still holds)")
    if as_json:
        click.echo(json.dumps({"out": str(res.out), "bytes": res.bytes, "start_ns": res.start_ns,
                               "end_ns": res.end_ns, "topics": res.topics}, indent=2))
    else:
        click.echo(f"{res.out}: {res.bytes:,} bytes")


def _command_named(args: list[str]) -> str | None:
    """The subcommand in a command line: the first word that is neither an option of the root
    group nor the value of one (``thermcap --config f.toml serve`` -> ``serve``)."""
    takes_value = {o for p in cli.params if isinstance(p, click.Option) and not p.is_flag and not p.count
                   for o in p.opts}
    skip = False
    for a in args:
        if skip:
            skip = False
        elif a in takes_value:
            skip = True
        elif not a.startswith("-"):
            return a
    return None


def main() -> None:
    """The console entry point: an error thermcap expected (a ThermcapError) or one from the disk
    (an OSError) is one line naming the file and exit 1, never a traceback."""
    import sys

    try:
        cli(prog_name="thermcap")
    except ModuleNotFoundError as exc:
        from thermcap.extras import missing_extra_message

        message = missing_extra_message(exc, _command_named(sys.argv[1:]))
        if message is None:
            raise
        fail(message)
    except ThermcapError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}")
