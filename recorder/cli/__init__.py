"""The recorder's subcommands, one module per group (importing them registers them on
``root.cli``), and the options every room's commands share (``options``)."""

from thermcap.recorder.cli import (  # noqa: F401  (registers the commands)
    analyze,
    files,
    listing,
    live,
    record,
    report,
    sync,
)
from thermcap.recorder.cli.options import default_root, fail, json_option, root_option
from thermcap.recorder.cli.root import cli

__all__ = ["cli", "default_root", "fail", "json_option", "root_option"]
