"""The one grammar of sizes a user types, for every option that takes one (``record --max-disk``,
``--min-free``, ``--max-protected``, ``gc --max-bytes``): ``123456`` is bytes; ``K``, ``M``, ``G``
and ``T`` count in powers of 1024, as ``df -h`` and ``du -h`` print them, and so do ``KiB`` ...
``TiB``; ``KB`` ... ``TB`` count in powers of 1000, as disk makers label them. A fraction is
allowed (``1.5T``); a negative, infinite or absurd size is refused, naming what was typed."""

from __future__ import annotations

import re

__all__ = ["parse_size"]

_SIZE = re.compile(r"^\s*(?P<number>\d+(?:\.\d*)?|\.\d+)\s*(?P<unit>[KMGT]?)(?P<suffix>I?B?)\s*$", re.IGNORECASE)
_POWER = {"": 0, "K": 1, "M": 2, "G": 3, "T": 4}


def parse_size(text: str | int) -> int:
    """Bytes in ``text`` (see the module docstring)."""
    m = _SIZE.match(str(text))
    if m is None:
        raise ValueError(f"{text!r} is not a size (for example 500M, 20G, 2TB, 123456)")
    unit, suffix = m["unit"].upper(), m["suffix"].upper()
    if not unit and suffix not in ("", "B"):
        raise ValueError(f"{text!r} is not a size (for example 500M, 20G, 2TB, 123456)")
    base = 1000 if suffix == "B" and unit else 1024
    value = float(m["number"]) * base ** _POWER[unit]
    if not value < 1 << 62:
        raise ValueError(f"{text!r} is more than any disk holds")
    return int(value)
