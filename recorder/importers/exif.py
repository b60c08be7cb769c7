"""The few EXIF and XMP fields importers need (make, model, capture time, drone-dji position)."""

from __future__ import annotations

import re
import struct
from datetime import datetime, timezone

__all__ = ["exif_fields", "xmp_fields", "exif_time_ns"]

_TAGS = {0x010F: "Make", 0x0110: "Model", 0x0132: "DateTime", 0x9003: "DateTimeOriginal", 0x8769: "ExifIFD"}


def exif_fields(app1_payloads: list[bytes]) -> dict[str, object]:
    """Make, Model, DateTime(Original) from an APP1 'Exif\\0\\0' payload; {} if absent or broken."""
    for p in app1_payloads:
        if not p.startswith(b"Exif\x00\x00"):
            continue
        t = p[6:]
        try:
            order = {b"II": "<", b"MM": ">"}[t[:2]]
            out: dict[str, object] = {}

            def walk(offset: int, depth: int = 0) -> None:
                (n,) = struct.unpack(order + "H", t[offset:offset + 2])
                for i in range(min(n, 512)):
                    e = t[offset + 2 + 12 * i: offset + 14 + 12 * i]
                    tag, typ, count = struct.unpack(order + "HHI", e[:8])
                    name = _TAGS.get(tag)
                    if name is None:
                        continue
                    if name == "ExifIFD" and depth == 0:
                        walk(struct.unpack(order + "I", e[8:12])[0], 1)
                    elif typ == 2:  # ASCII
                        off = struct.unpack(order + "I", e[8:12])[0] if count > 4 else None
                        raw = e[8:8 + count] if off is None else t[off:off + count]
                        out[name] = raw.split(b"\x00")[0].decode("latin-1").strip()

            (ifd0,) = struct.unpack(order + "I", t[4:8])
            walk(ifd0)
            return out
        except (KeyError, struct.error, IndexError):
            return {}
    return {}


def xmp_fields(app1_payloads: list[bytes]) -> dict[str, str]:
    """drone-dji:* attributes of the XMP packet (GPS, altitudes, gimbal and flight attitude, ...)."""
    for p in app1_payloads:
        if p.startswith(b"http://ns.adobe.com/xap/1.0/"):
            text = p.decode("utf-8", "replace")
            found = dict(re.findall(r'drone-dji:(\w+)="([^"]*)"', text))
            found.update(re.findall(r"<drone-dji:(\w+)>([^<]*)</drone-dji:\1>", text))
            return found
    return {}


def exif_time_ns(value: str | None) -> int | None:
    """'2021:03:04 12:34:56' (camera local time, taken as UTC when no zone is known) -> ns."""
    if not value:
        return None
    try:
        dt = datetime.strptime(value[:19], "%Y:%m:%d %H:%M:%S").replace(tzinfo=timezone.utc)
    except ValueError:
        return None
    return int(dt.timestamp()) * 1_000_000_000
