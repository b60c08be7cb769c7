"""The recorder's subcommands gather on this group; the ``thermcap`` command itself (its
root options, the other rooms' subcommands, ``main``) is composed in ``thermcap.cli``, above all
three packages, so the recorder never imports the archive or the API."""

from __future__ import annotations

import click

__all__ = ["cli"]


@click.group()
def cli() -> None:
    """The recorder's commands (record, ctl, info, export, ...); ``thermcap.cli`` adds them to the root."""

