"""The few EXIF and XMP fields importers need (make, model, capture time, drone-dji position)."""

from __future__ import annotations

import re
import struct
from datetime import UTC, datetime

__all__ = ["capture_time", "exif_fields", "exif_position", "exif_time_ns", "xmp_fields"]

_TAGS = {0x010F: "Make", 0x0110: "Model", 0x0132: "DateTime", 0x9003: "DateTimeOriginal", 0x8769: "ExifIFD",
         0x8825: "GPSIFD", 0x9010: "OffsetTime", 0x9011: "OffsetTimeOriginal", 0x9291: "SubSecTimeOriginal",
         0x920A: "FocalLength", 0xA405: "FocalLengthIn35mmFilm"}
_GPS_TAGS = {0x0001: "GPSLatitudeRef", 0x0002: "GPSLatitude", 0x0003: "GPSLongitudeRef", 0x0004: "GPSLongitude",
             0x0005: "GPSAltitudeRef", 0x0006: "GPSAltitude", 0x0007: "GPSTimeStamp", 0x0012: "GPSMapDatum",
             0x001D: "GPSDateStamp"}


def _walk_ifd(t: bytes, order: str, out: dict[str, object], offset: int, tags: dict[int, str],
              depth: int = 0) -> None:
    """One IFD's tags into ``out``; the Exif and GPS sub-IFDs once, one level deep."""
    (n,) = struct.unpack(order + "H", t[offset:offset + 2])
    for i in range(min(n, 512)):
        e = t[offset + 2 + 12 * i: offset + 14 + 12 * i]
        tag, typ, count = struct.unpack(order + "HHI", e[:8])
        name = tags.get(tag)
        if name is None:
            continue
        if name in ("ExifIFD", "GPSIFD") and depth == 0:
            _walk_ifd(t, order, out, struct.unpack(order + "I", e[8:12])[0],
                      _GPS_TAGS if name == "GPSIFD" else _TAGS, 1)
        elif typ == 2:  # ASCII
            off = struct.unpack(order + "I", e[8:12])[0] if count > 4 else None
            raw = e[8:8 + count] if off is None else t[off:off + count]
            out[name] = raw.split(b"\x00")[0].decode("latin-1").strip()
        elif typ == 5 and count in (1, 3):  # RATIONAL: GPS degrees/minutes/seconds, a time, an altitude
            (off,) = struct.unpack(order + "I", e[8:12])
            v = struct.unpack(order + f"{2 * count}I", t[off:off + 8 * count])
            vals = tuple(a / b if b else 0.0 for a, b in zip(v[::2], v[1::2], strict=True))
            out[name] = vals if count == 3 else vals[0]
        elif typ == 1 and count == 1:  # BYTE: GPSAltitudeRef (1: below sea level)
            out[name] = e[8]
        elif typ == 3 and count == 1:  # SHORT: FocalLengthIn35mmFilm
            out[name] = struct.unpack(order + "H", e[8:10])[0]


def exif_fields(app1_payloads: list[bytes]) -> dict[str, object]:
    """Make, Model, DateTime(Original), its offset and sub-seconds, and the GPS date and time from an
    APP1 'Exif\\0\\0' payload; {} if absent or broken."""
    for p in app1_payloads:
        if not p.startswith(b"Exif\x00\x00"):
            continue
        t = p[6:]
        try:
            order = {b"II": "<", b"MM": ">"}[t[:2]]
            out: dict[str, object] = {}

            (ifd0,) = struct.unpack(order + "I", t[4:8])
            _walk_ifd(t, order, out, ifd0, _TAGS)
            return out
        except (KeyError, struct.error, IndexError):
            return {}
    return {}


def exif_position(exif: dict[str, object]) -> dict[str, object] | None:
    """The EXIF GPS position as signed decimal degrees (and metres), or None without a fix."""
    lat, lon = exif.get("GPSLatitude"), exif.get("GPSLongitude")
    if not isinstance(lat, tuple) or not isinstance(lon, tuple) or len(lat) != 3 or len(lon) != 3:
        return None
    dec = lambda v: v[0] + v[1] / 60 + v[2] / 3600  # noqa: E731
    la = dec(lat) * (-1 if exif.get("GPSLatitudeRef") == "S" else 1)
    lo = dec(lon) * (-1 if exif.get("GPSLongitudeRef") == "W" else 1)
    if la == 0 and lo == 0:
        return None  # an empty fix, not the Gulf of Guinea
    alt = exif.get("GPSAltitude")
    out: dict[str, object] = {"latitude": la, "longitude": lo, "source": "EXIF GPS",
                              "datum": exif.get("GPSMapDatum") or "WGS84"}
    if isinstance(alt, float):
        out["altitude_m"] = -alt if exif.get("GPSAltitudeRef") == 1 else alt
    return out


def xmp_fields(app1_payloads: list[bytes], prefix: str = "drone-dji") -> dict[str, str]:
    """The ``prefix:*`` properties of the XMP packet, written as attributes or as elements:
    ``drone-dji`` (GPS, altitudes, gimbal and flight attitude), Pix4D's ``Camera`` (FLIR drone
    cameras' attitude), ``FLIR`` (MAVLink altitude and attitude)."""
    ns = re.escape(prefix)
    for p in app1_payloads:
        if p.startswith(b"http://ns.adobe.com/xap/1.0/"):
            text = p.decode("utf-8", "replace")
            found = dict(re.findall(rf'\b{ns}:(\w+)="([^"]*)"', text))
            found.update(re.findall(rf"<{ns}:(\w+)>([^<]*)</{ns}:\1>", text))
            return found
    return {}


def exif_time_ns(value: str | None) -> int | None:
    """'2021:03:04 12:34:56' (camera local time, taken as UTC when no zone is known) -> ns."""
    if not value:
        return None
    try:
        dt = datetime.strptime(value[:19], "%Y:%m:%d %H:%M:%S").replace(tzinfo=UTC)
    except ValueError:
        return None
    return int(dt.timestamp()) * 1_000_000_000


def capture_time(exif: dict[str, object], xmp: dict[str, str] | None = None) -> tuple[int | None, str]:
    """The best capture time a JPEG states, as UTC ns, and what it rests on.

    In order: DJI's XMP ``UTCAtExposure``; EXIF DateTimeOriginal with its OffsetTimeOriginal; the
    EXIF GPS date and time (UTC by definition); last, DateTimeOriginal alone, which is the camera's
    local time in an unknown zone, taken as UTC and said so (frames of one camera still order
    correctly)."""
    from thermcap.recorder.icd.names import parse_rfc3339

    stamp = (xmp or {}).get("UTCAtExposure")
    if stamp:
        try:
            stamp = stamp.strip().replace(" ", "T")
            if stamp[4:5] == ":" and stamp[7:8] == ":":  # DJI writes EXIF-style "2023:04:18 07:46:52.442"
                stamp = f"{stamp[:4]}-{stamp[5:7]}-{stamp[8:]}"
            return parse_rfc3339(stamp if stamp.endswith("Z") else stamp + "Z"), "utc: drone-dji UTCAtExposure"
        except ValueError:
            pass
    local = str(exif.get("DateTimeOriginal") or exif.get("DateTime") or "")
    base = exif_time_ns(local)
    if base is not None:
        sub = str(exif.get("SubSecTimeOriginal") or "")
        if sub.isdigit():
            base += int(sub.ljust(9, "0")[:9])
        offset = str(exif.get("OffsetTimeOriginal") or exif.get("OffsetTime") or "")
        m = re.fullmatch(r"([+-])(\d\d):(\d\d)", offset)
        if m:
            minutes = (int(m[2]) * 60 + int(m[3])) * (1 if m[1] == "+" else -1)
            return base - minutes * 60_000_000_000, f"exif: local time with offset {offset}"
    date, hms = exif.get("GPSDateStamp"), exif.get("GPSTimeStamp")
    if isinstance(date, str) and isinstance(hms, tuple) and len(hms) == 3:
        day = exif_time_ns(date[:10] + " 00:00:00")
        if day is not None:
            return day + round((hms[0] * 3600 + hms[1] * 60 + hms[2]) * 1e9), "utc: exif GPS date and time"
    if base is not None:
        return base, "camera local time, zone unknown (taken as UTC)"
    return None, "none stated (file modification time used)"
