"""The ``thermcap`` root group and its plugin mechanism.

Other packages add their subcommands through the ``thermcap.commands`` and ``thermcap.bench``
entry-point groups (see pyproject.toml), so the recorder never imports the archive or the API.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any

import click

from recorder import __version__
from recorder.cli.options import fail
from recorder.exceptions import ThermcapError

__all__ = ["bench", "cli", "main"]


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
@click.option("--config", "config", envvar="THERMCAP_CONFIG", show_envvar=True, default=None, metavar="FILE",
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
        from recorder.cli.config import load_config

        assert isinstance(ctx.command, click.Group)
        ctx.default_map = load_config(config, ctx.command, ctx)


@cli.group(cls=_PluginGroup, entry_point_group="thermcap.bench")
def bench() -> None:
    """Benchmarks: each prints ratios against a baseline measured in the same run."""


def main() -> None:
    """The console entry point: an error thermcap expected (a ThermcapError) or one from the disk
    (an OSError) is one line naming the file and exit 1, never a traceback."""
    try:
        cli(prog_name="thermcap")
    except ThermcapError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}")
