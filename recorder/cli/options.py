"""Options and helpers every package's subcommands share: the data root, ``--json``, and ``fail``."""

from __future__ import annotations

import os
import sys
from typing import NoReturn

import click

__all__ = ["default_root", "fail", "json_option", "root_option"]


def default_root() -> str:
    return os.environ.get("THERMCAP_ROOT", "thermcap-data")


def fail(message: str, code: int = 1) -> NoReturn:
    click.echo(f"error: {message}", err=True)
    sys.exit(code)


root_option = click.option("--root", default=default_root, show_default="$THERMCAP_ROOT or ./thermcap-data",
                           type=click.Path(file_okay=False), help="Data root (sessions live in ROOT/sessions).")
json_option = click.option("--json", "as_json", is_flag=True, help="Print machine-readable JSON.")

