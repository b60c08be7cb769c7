"""CDR (little-endian, XCDR1): the library's encoder for messages written now and then, and the
pieces the two messages written with every frame are laid out by hand with.

Why two ways: the sidecar and the targets' marks go with every frame, on the recorder's writer
thread, where a generic encoder (looking every field up, coercing it) costs a noticeable share
of the recorder's CPU; ``thermcap bench cdr`` measures the hand layouts against mcap_ros2's and
rosbags' encoders in one run. Everything else (stats once a second, events, cues, other JSON
documents) is encoded by mcap_ros2, the library that also parses the definitions, so no
home-made encoder stands where speed does not ask for one. The tests compare every hand-laid
message with mcap_ros2's bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from functools import cache
from typing import Any

__all__ = ["library_encoder", "pad", "phase_layouts", "write_string"]


def pad(out: bytearray, size: int) -> None:
    """Public, with ``write_string``, so a message laid out by hand (the marks, the sidecar) pads as CDR does."""
    # the four-byte encapsulation header does not count towards alignment
    gap = -(len(out) - 4) % size
    if gap:
        out += b"\0" * gap


#: a string's length, after the padding that 4-aligns it, by the offset modulo 4
_LENGTH_AT = [struct.Struct("<" + "x" * (-phase % 4) + "I") for phase in range(4)]


def write_string(out: bytearray, value: Any) -> None:
    data = (value if value.__class__ is str else "" if value is None else str(value)).encode("utf-8")
    out += _LENGTH_AT[(len(out) - 4) % 4].pack(len(data) + 1)  # the header's four bytes do not count
    out += data
    out.append(0)


def phase_layouts(codes: list[str]) -> list[struct.Struct]:
    """A run of fixed-size fields (struct codes, one field each) as one struct per offset the run
    can start at, modulo 8: CDR pads each field to its own size counted from the stream's start,
    so the padding inside the run depends on where it starts. ``layouts[(len(out) - 4) % 8]``."""
    layouts = []
    for phase in range(8):
        fmt, at = "<", phase
        for code in codes:
            size = struct.calcsize(code)
            gap = -at % size
            fmt += "x" * gap + code
            at += gap + size
        layouts.append(struct.Struct(fmt))
    return layouts


@cache
def library_encoder(schema_name: str, schema_text: str) -> Callable[[dict[str, Any]], bytes]:
    """mcap_ros2's encoder for a ros2msg definition (dependencies concatenated, as MCAP's ros2
    profile embeds them): a dict in, CDR bytes out (missing fields as ROS 2 defaults)."""
    from mcap_ros2._dynamic import serialize_dynamic  # the function mcap_ros2's own Writer encodes with

    return serialize_dynamic(schema_name, schema_text)[schema_name]
