"""Every option's default passes the option's own check: ``thermcap bench index`` once refused
its own default (``--frames 10000000 is above 1e+06``) before doing anything."""

from __future__ import annotations

from collections.abc import Iterator

import click
import pytest

from thermcap.cli import cli as main


def _commands(group: click.Command, path: str = "thermcap") -> Iterator[tuple[str, click.Command]]:
    yield path, group
    if isinstance(group, click.Group):
        ctx = click.Context(group)
        for name in group.list_commands(ctx):
            sub = group.get_command(ctx, name)
            if sub is not None:
                yield from _commands(sub, f"{path} {name}")


@pytest.mark.parametrize(("path", "command"), list(_commands(main)), ids=lambda v: v if isinstance(v, str) else "")
def test_every_default_is_a_value_the_option_takes(path, command):
    for param in command.params:
        if not isinstance(param, click.Option):
            continue
        # what the option falls back to (click 8.3 and later mark an option given no default
        # with a sentinel of their own, which get_default turns into None)
        default = param.get_default(click.Context(command), call=False)
        if default is None or callable(default):
            continue
        if param.multiple or param.nargs != 1 or isinstance(param.type, click.Choice | click.Path):
            continue
        try:
            param.type.convert(default, param, click.Context(command))
        except click.BadParameter as exc:
            pytest.fail(f"{path} {param.opts[0]}: its default {default!r} is refused: {exc.message}")
