"""Options and helpers every package's subcommands share: the data root, ``--json``, and ``fail``."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, NoReturn, TypeVar

import click

from thermcap.recorder import settings

__all__ = ["PORT", "Number", "default_root", "fail", "json_option", "port_option", "root_option"]

F = TypeVar("F", bound=Callable[..., Any])


def default_root() -> str:
    return settings.ROOT.text()


def fail(message: str, code: int = 1) -> NoReturn:
    click.echo(f"error: {message}", err=True)
    sys.exit(code)


root_option = click.option("--root", default=default_root, show_default="$THERMCAP_ROOT or ./thermcap-data",
                           type=click.Path(file_okay=False), help="Data root (sessions live in ROOT/sessions).")
json_option = click.option("--json", "as_json", is_flag=True, help="Print machine-readable JSON.")



class Number(click.ParamType):
    """A finite number within bounds, refused at parse time in the option's own terms (click's
    FloatRange takes ``inf`` and ``nan``, which then fail deep inside the recorder)."""

    name = "number"

    def __init__(self, *, minimum: float | None = None, maximum: float | None = None, above: bool = False,
                 integer: bool = False, unit: str = "") -> None:
        self.minimum, self.maximum, self.above, self.integer, self.unit = minimum, maximum, above, integer, unit
        self.name = "integer" if integer else "number"

    def convert(self, value, param, ctx):
        import math

        if isinstance(value, int | float) and not isinstance(value, bool):
            number = float(value)
        else:
            try:
                number = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.integer and number != int(number):
            self.fail(f"{value!r} is not a whole number", param, ctx)
        unit = f" {self.unit}" if self.unit else ""
        if self.minimum is not None and (number <= self.minimum if self.above else number < self.minimum):
            self.fail(f"{value} is {'not above' if self.above else 'below'} {self.minimum:g}{unit}", param, ctx)
        if self.maximum is not None and number > self.maximum:
            self.fail(f"{value} is above {self.maximum:g}{unit}", param, ctx)
        return int(number) if self.integer else number


class Size(click.ParamType):
    """A size in bytes, in the one grammar every size option takes (``recorder.sizes``)."""

    name = "size"

    def convert(self, value, param, ctx):
        from thermcap.recorder.sizes import parse_size

        if isinstance(value, int) and not isinstance(value, bool):
            return value
        try:
            return parse_size(value)
        except ValueError as exc:
            self.fail(str(exc), param, ctx)


SIZE = Size()

#: The ports a user may name (0: any free one).
PORT = Number(minimum=0, maximum=65535, integer=True)


def port_option(*names: str, default: int, help: str) -> Callable[[F], F]:
    return click.option(*names, type=PORT, default=default, show_default=True, help=help)


def parse_instant(value: str | None, first_ns: int, name: str) -> int | None:
    """An RFC 3339 time, or seconds from the session's first frame (``12.5``): what ``--start``
    and ``--end`` take in ``cut`` and ``export``."""
    from thermcap.recorder.icd.names import parse_rfc3339

    if value is None:
        return None
    try:
        seconds = float(value)
    except ValueError:
        try:
            return parse_rfc3339(value)
        except ValueError as exc:
            raise ValueError(f"--{name} {value!r}: an RFC 3339 time or seconds from the first frame ({exc})") from None
    if not seconds >= 0 or seconds == float("inf"):
        raise ValueError(f"--{name} {value!r}: seconds from the first frame must be 0 or more")
    return first_ns + round(seconds * 1e9)
