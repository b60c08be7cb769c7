"""The ``thermcap`` command: the root group (``root``), shared options (``options``), and the
recorder's own subcommands, one module per group; importing them registers them on the group."""

from recorder.cli import analyze, bench, files, live, record, report, sync  # noqa: F401  (registers the commands)
from recorder.cli.options import default_root, fail, json_option, root_option
from recorder.cli.root import cli, main

__all__ = ["cli", "default_root", "fail", "json_option", "main", "root_option"]
