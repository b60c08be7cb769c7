"""Capture times from JPEG metadata: which statement wins, and what each rests on."""

from __future__ import annotations

import struct

from thermcap.recorder.icd.names import iso_utc
from thermcap.recorder.importers.exif import capture_time, exif_fields


def _exif(ifd0: dict[int, bytes], exif: dict[int, bytes] | None = None, gps: dict[int, tuple] | None = None) -> bytes:
    """A little-endian EXIF APP1 payload: ASCII tags in IFD0 and the Exif IFD, RATIONAL x3 or
    ASCII in the GPS IFD (enough to exercise the reader the way cameras write it)."""
    blobs = bytearray()
    layout: list[tuple[str, dict]] = [("ifd0", ifd0), ("exif", exif or {}), ("gps", gps or {})]
    sizes = {name: 2 + 12 * (len(tags) + (name == "ifd0") * 2) + 4 for name, tags in layout}
    starts, pos = {}, 8
    for name, _ in layout:
        starts[name] = pos
        pos += sizes[name]
    data_at = pos
    out = bytearray(b"II*\x00" + struct.pack("<I", 8))

    def entries(tags: dict, extra: list[tuple[int, int, int, int]]) -> bytes:
        nonlocal data_at
        ents = []
        for tag, value in sorted(tags.items()):
            if isinstance(value, tuple):  # RATIONAL x3
                payload = b"".join(struct.pack("<II", int(v * 1000), 1000) for v in value)
                ents.append(struct.pack("<HHII", tag, 5, 3, data_at))
            else:
                payload = value + b"\x00"
                if len(payload) <= 4:  # short values sit in the entry itself
                    ents.append(struct.pack("<HHI", tag, 2, len(payload)) + payload.ljust(4, b"\x00"))
                    continue
                ents.append(struct.pack("<HHII", tag, 2, len(payload), data_at))
            blobs.extend(payload)
            data_at += len(payload)
        ents += [struct.pack("<HHII", *e) for e in extra]
        return struct.pack("<H", len(ents)) + b"".join(sorted(ents, key=lambda e: e[:2][::-1])) + b"\x00" * 4

    out += entries(ifd0, [(0x8769, 4, 1, starts["exif"]), (0x8825, 4, 1, starts["gps"])])
    out += entries(exif or {}, [])
    out += entries(gps or {}, [])
    return b"Exif\x00\x00" + bytes(out) + bytes(blobs)


def test_offset_time_original_gives_utc():
    app1 = _exif({0x010F: b"DJI"}, {0x9003: b"2024:11:22 18:33:03", 0x9011: b"+08:00", 0x9291: b"25"})
    fields = exif_fields([app1])
    assert fields["Make"] == "DJI"
    assert fields["OffsetTimeOriginal"] == "+08:00"
    ns, basis = capture_time(fields)
    assert iso_utc(ns).startswith("2024-11-22T10:33:03.25")
    assert "offset +08:00" in basis


def test_gps_date_and_time_are_utc_when_no_offset_is_given():
    app1 = _exif({}, {0x9003: b"2024:11:22 18:33:03"}, {0x001D: b"2024:11:22", 0x0007: (10.0, 33.0, 3.5)})
    ns, basis = capture_time(exif_fields([app1]))
    assert iso_utc(ns).startswith("2024-11-22T10:33:03.5")
    assert basis == "utc: exif GPS date and time"


def test_xmp_utc_wins_and_a_bare_local_time_says_its_zone_is_unknown():
    fields = exif_fields([_exif({}, {0x9003: b"2021:05:28 10:33:46"})])
    for stamp in ("2021-05-28T02:33:46.120000", "2021:05:28 02:33:46.120"):  # as DJI writes it; EXIF-style
        ns, basis = capture_time(fields, {"UTCAtExposure": stamp})
        assert iso_utc(ns).startswith("2021-05-28T02:33:46.12")
        assert basis == "utc: drone-dji UTCAtExposure"
    ns, basis = capture_time(fields)
    assert iso_utc(ns).startswith("2021-05-28T10:33:46")
    assert "zone unknown" in basis
    assert capture_time({}) == (None, "none stated (file modification time used)")
