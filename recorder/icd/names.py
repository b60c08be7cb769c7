"""Constants and the file-naming convention of the Thermal Data ICD (shared/specs/thermal-data-icd.md).

The naming convention (ICD 2.1) is ``thermal_<UTC timestamp>_<sensor_id>_<scene_temp_range>``,
e.g. ``thermal_20260111T153045Z_BOSON640_N40_P60``. We keep sub-second precision as an optional
``.ffffff`` or ``.fffffffff`` fraction after the seconds, because a 60 fps camera needs it to give
every frame its own name; names without it parse too.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import UTC, datetime

__all__ = [
    "CROSSOVER_GRADE",
    "DETECTION_THRESHOLD_K",
    "EXCELLENT_THRESHOLD_K",
    "FORMAT_VERSION",
    "MAX_COUNT",
    "IcdName",
    "format_name",
    "format_temp_range",
    "iso_utc",
    "parse_name",
    "parse_rfc3339",
]

FORMAT_VERSION = "1.0"
BIT_DEPTH = 14
MAX_COUNT = (1 << BIT_DEPTH) - 1  # 16383
DETECTION_THRESHOLD_K = 5.0
EXCELLENT_THRESHOLD_K = 10.0
CROSSOVER_GRADE = 0.3

_NAME_RE = re.compile(
    r"^thermal_(?P<ts>\d{8}T\d{6})(?:\.(?P<frac>\d{1,9}))?Z_(?P<sensor>[A-Za-z0-9-]+)_"
    r"(?P<tmin>[NP]\d+)_(?P<tmax>[NP]\d+)$"
)


@dataclass(frozen=True)
class IcdName:
    timestamp_ns: int
    sensor_id: str
    temp_min_c: int
    temp_max_c: int


def _signed(value: int) -> str:
    return f"{'N' if value < 0 else 'P'}{abs(int(value))}"


def format_temp_range(temp_min_c: float, temp_max_c: float) -> str:
    """``-40, 60`` -> ``N40_P60`` (whole degrees, as the ICD example)."""
    return f"{_signed(round(temp_min_c))}_{_signed(round(temp_max_c))}"


def _sanitize_sensor(sensor_id: str) -> str:
    clean = re.sub(r"[^A-Za-z0-9-]", "", sensor_id)
    if not clean:
        raise ValueError(f"sensor id {sensor_id!r} has no characters usable in an ICD file name")
    return clean


def format_name(timestamp_ns: int, sensor_id: str, temp_min_c: float, temp_max_c: float,
                *, subsecond: bool = True) -> str:
    """The ICD base name (no extension) for a frame captured at ``timestamp_ns`` (Unix, UTC)."""
    seconds, frac_ns = divmod(int(timestamp_ns), 1_000_000_000)
    stamp = datetime.fromtimestamp(seconds, tz=UTC).strftime("%Y%m%dT%H%M%S")
    if subsecond:
        stamp += f".{frac_ns:09d}"
    return f"thermal_{stamp}Z_{_sanitize_sensor(sensor_id)}_{format_temp_range(temp_min_c, temp_max_c)}"


def parse_name(name: str) -> IcdName:
    """Parse an ICD base name (an extension such as ``.tiff`` or ``.json`` is ignored)."""
    base = re.sub(r"(\.(celsius|kelvin))?\.(tiff?|json|raw|gray16|png)$", "", name.rsplit("/", 1)[-1], flags=re.I)
    m = _NAME_RE.match(base)
    if not m:
        raise ValueError(
            f"{name!r} does not follow the ICD naming convention "
            "thermal_<YYYYMMDDTHHMMSS[.fraction]Z>_<sensor>_<N|P><min>_<N|P><max>"
        )
    dt = datetime.strptime(m["ts"], "%Y%m%dT%H%M%S").replace(tzinfo=UTC)
    frac = m["frac"] or ""
    ns = int(dt.timestamp()) * 1_000_000_000 + (int(frac.ljust(9, "0")) if frac else 0)

    def unsigned(tok: str) -> int:
        return -int(tok[1:]) if tok[0] == "N" else int(tok[1:])

    return IcdName(ns, m["sensor"], unsigned(m["tmin"]), unsigned(m["tmax"]))


_last_second: tuple[int, str] = (0, "1970-01-01T00:00:00")


def iso_utc(ns: int) -> str:
    """RFC 3339 UTC with nanoseconds (the sidecar's capture.timestamp and the API's times).

    The formatted second is kept from one call to the next: a camera's frames come many to a
    second, and formatting the date took three quarters of the call."""
    global _last_second
    sec, frac = divmod(int(ns), 1_000_000_000)
    last = _last_second  # one read: another thread may replace it, never half-way
    if last[0] != sec:
        last = _last_second = (sec, datetime.fromtimestamp(sec, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S"))
    return f"{last[1]}.{frac:09d}Z"


_RFC3339 = re.compile(r"^(\d{4}-\d\d-\d\d)[Tt ](\d\d:\d\d:\d\d)(?:\.(\d{1,9}))?(Z|z|[+-]\d\d:\d\d)$")


def parse_rfc3339(text: str) -> int:
    """RFC 3339 -> Unix ns, keeping every digit of the fraction (datetime stops at microseconds)."""
    m = _RFC3339.match(text.strip())
    if not m:
        raise ValueError(f"{text!r} is not an RFC 3339 time like 2026-11-23T19:15:41.336745723Z")
    base = datetime.strptime(f"{m[1]}T{m[2]}", "%Y-%m-%dT%H:%M:%S")
    tz = m[4].upper()
    offset = 0 if tz == "Z" else (1 if tz[0] == "+" else -1) * (int(tz[1:3]) * 3600 + int(tz[4:6]) * 60)
    sec = int(base.replace(tzinfo=UTC).timestamp()) - offset
    return sec * 1_000_000_000 + int((m[3] or "0").ljust(9, "0"))
