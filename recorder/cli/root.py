"""The recorder's subcommands gather on these two groups; the ``thermcap`` command itself (its
root options, the other rooms' subcommands, ``main``) is composed in ``thermcap.cli``, above all
three packages, so the recorder never imports the archive or the API."""

from __future__ import annotations

import click

__all__ = ["bench", "cli"]


@click.group()
def cli() -> None:
    """The recorder's commands (record, ctl, info, export, ...); ``thermcap.cli`` adds them to the root."""


@click.group()
def bench() -> None:
    """The recorder's benchmarks; ``thermcap.cli`` merges them into ``thermcap bench``."""
