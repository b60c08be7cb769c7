"""DJI R-JPEG: layout detection (iirp, dirp incl. Zenmuse XT S, girp, hirp), the raw frame
bit-exact, the embedded measurement parameters and every calibration blob (formats.md 1).

The thermal frame's size never comes from the JPEG's own size (an M30T JPEG is 1280x1024
around a 640x512 frame); it comes from the layout's own header, and the raw payload must match
it exactly.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.importers.base import ImportedFrame, ImportFileError
from thermcap.recorder.importers.exif import capture_time, exif_fields, xmp_fields
from thermcap.recorder.importers.jpeg import app_segments, concat_app
from thermcap.recorder.radiometry import DjiModel

__all__ = ["DJI_SEGMENT", "RAW_PLACEHOLDER", "SEGMENTS_BLOB", "app_segment", "dji_layout", "is_dji",
           "kept_rjpeg_segments", "read_dji"]

_MAGIC = b"\xff\xd2\xd1\xff"
SEGMENTS_BLOB = "dji_rjpeg_segments.bin"
RAW_PLACEHOLDER = b"thermcap:raw-frame\x00"
DJI_SEGMENT = 65532  # DJI splits a blob into segments of this payload size (formats.md 1.1)


def app_segment(marker: int, payload: bytes) -> bytes:
    return b"\xff" + bytes([marker]) + struct.pack(">H", len(payload) + 2) + payload


def _app_segments_without_raw(segments: list[tuple[int, bytes]], raw_marker: int) -> bytes:
    """Every APPn segment in file order, bit-exact, with the raw frame's run of segments replaced
    by one placeholder: with the stored frame, enough to rebuild an R-JPEG DJI's SDK measures."""
    out, placed = [], False
    for marker, payload in segments:
        if not 0xE0 <= marker <= 0xEF:
            continue
        if marker == raw_marker:
            if not placed:
                out.append(app_segment(marker, RAW_PLACEHOLDER))
                placed = True
            continue
        out.append(app_segment(marker, payload))
    return b"".join(out)


def kept_rjpeg_segments(session_dir: Path) -> dict[int, tuple[str, bytes]]:
    """Per log time: the source file's name and its kept APP segments, from the MCAP source or,
    once that is deleted, the archive's extras.mcap (which keeps every attachment as recorded)."""
    from mcap.reader import make_reader

    from thermcap.recorder.storage.layout import SessionLayout

    files = sorted(session_dir.glob("[0-9][0-9][0-9][0-9].mcap"))
    if not files and SessionLayout.of(session_dir).extras.is_file():
        files = [SessionLayout.of(session_dir).extras]
    out: dict[int, tuple[str, bytes]] = {}
    for seg in files:
        with open(seg, "rb") as f:
            for att in make_reader(f, validate_crcs=True).iter_attachments():
                if att.name.endswith("/" + SEGMENTS_BLOB):
                    out[att.log_time] = (att.name[: -len(SEGMENTS_BLOB) - 1], att.data)
    return out


def _rounded(params: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if v is None else round(float(v), 6)) for k, v in params.items()}


def is_dji(segments: list[tuple[int, bytes]]) -> bool:
    exif = exif_fields([p for m, p in segments if m == 0xE1])
    app4 = concat_app(segments, 0xE4)
    return (str(exif.get("Make", "")).upper().startswith("DJI") and exif.get("Model") != "FLIR") or \
        app4[:4] == _MAGIC or (bool(concat_app(segments, 0xE3)) and str(exif.get("Model", "")) in ("ZH20T", "XT S"))


def dji_layout(model: str, app3: bytes, app4: bytes) -> str:
    layout = None
    if model in ("ZH20T", "XT S"):
        layout = "dirp"
    elif model == "MAVIC2-ENTERPRISE-ADVANCED" and len(app3) == 640 * 512 * 2:
        layout = "iirp"
    if app4[:4] == _MAGIC and len(app4) >= 12:
        tag = app4[4:12].split(b"\x00")[0].decode("ascii", "replace")
        if tag in ("iirp", "girp", "hirp", "dirp"):
            layout = tag
    if layout is None:
        raise ImportFileError(f"unsupported DJI thermal layout (EXIF model {model!r}, APP4 starts {app4[:12]!r})")
    return layout


def _size(path: str, layout: str, model: str, app4: bytes) -> tuple[int, int]:
    if layout == "iirp" and app4[:4] == _MAGIC:
        if len(app4) < 0xA1:
            raise ImportFileError(f"{path}: DJI iirp parameter block too short ({len(app4)} bytes)")
        return struct.unpack("<HH", app4[0x9D:0xA1])
    if layout == "hirp":
        if len(app4) < 0x30:
            raise ImportFileError(f"{path}: DJI hirp parameter block too short ({len(app4)} bytes)")
        return struct.unpack("<II", app4[0x28:0x30])
    return 640, 512


def _params(layout: str, model: str, app4: bytes) -> dict[str, float | None]:
    try:
        if layout == "iirp":
            base = 0x20 if app4[:4] == _MAGIC else 0
            amb, dist, emis, hum, refl = struct.unpack("<5f", app4[base:base + 20])
            return {"ambient_c": amb, "distance_m": dist, "emissivity": emis, "humidity_pct": hum * 100,
                    "reflection_c": refl}
        if layout == "dirp" and model == "ZH20T":
            dist, hum, emis, refl, amb = struct.unpack("<HHHhH", app4[0x44:0x4E])
            # 0x4C is DJI's "D1" constant, not an ambient temperature: not reported as one.
            return {"distance_m": float(dist), "humidity_pct": float(hum), "emissivity": emis / 100,
                    "reflection_c": refl / 10, "ambient_c": None}
        if layout == "girp":
            line = app4[32:]
            hum, dist, emis, refl = struct.unpack("<HHHh", line[4:12])
            return {"humidity_pct": float(hum), "distance_m": dist / 10, "emissivity": emis / 100,
                    "reflection_c": refl / 10, "ambient_c": None}  # not embedded (the SDK assumes 23 C)
        if layout == "hirp":
            tp = 0x20 + struct.unpack("<I", app4[0x24:0x28])[0]
            emis = struct.unpack("<H", app4[tp + 0x10:tp + 0x12])[0] / 8192
            dist = struct.unpack("<i", app4[tp + 0x14:tp + 0x18])[0] / 8192
            amb = struct.unpack("<i", app4[tp + 0x28:tp + 0x2C])[0] / 1000
            hum = struct.unpack("<i", app4[tp + 0x2C:tp + 0x30])[0] / 1000
            refl = struct.unpack("<i", app4[tp + 0x18:tp + 0x1C])[0] / 8192 if app4[tp + 0x1C] == 1 else amb
            return {"emissivity": emis, "distance_m": dist, "ambient_c": amb, "humidity_pct": hum, "reflection_c": refl}
    except (struct.error, IndexError):
        pass
    return {}


def read_dji(path: str, data: bytes) -> list[ImportedFrame]:
    segments = app_segments(path, data)
    app1 = [p for m, p in segments if m == 0xE1]
    exif = exif_fields(app1)
    model = str(exif.get("Model", ""))
    app3, app4, app5 = concat_app(segments, 0xE3), concat_app(segments, 0xE4), concat_app(segments, 0xE5)
    try:
        layout = dji_layout(model, app3, app4)
    except ImportFileError as exc:
        raise ImportFileError(f"{path}: {exc}") from None
    xt_s = layout == "dirp" and model == "XT S"
    w, h = _size(path, layout, model, app4)
    payload = app4 if xt_s else app3
    if len(payload) != w * h * 2:
        raise ImportFileError(f"{path}: DJI {layout} raw payload is {len(payload)} bytes, "
                           f"expected {w}x{h}x2 = {w * h * 2}")
    # Signed layouts (girp, XT S) keep their int16 bit pattern in the uint16 container: bit-exact.
    pixels = np.frombuffer(payload, dtype="<u2").reshape(h, w).copy()
    blobs = {}
    if app4 and not xt_s:
        blobs["dji_app4_params.bin"] = app4
    if app5:
        blobs["dji_app5_calibration.bin"] = app5
    if xt_s:
        blobs["dji_app3_curve.bin"] = app3
        plug = concat_app(segments, 0xE2)
        if plug.startswith(b"Plug"):
            blobs["dji_app2_plug.bin"] = plug
    blobs[SEGMENTS_BLOB] = _app_segments_without_raw(segments, 0xE4 if xt_s else 0xE3)
    params = _params(layout, model, app4)
    xmp = xmp_fields(app1)
    ts, time_basis = capture_time(exif, xmp)
    meta = {"exif_make": exif.get("Make"), "exif_model": model, "layout": layout, "embedded_params": params,
            "exif_focal_length_mm": exif.get("FocalLength"),
            "exif_focal_length_35mm": exif.get("FocalLengthIn35mmFilm"),
            "signed_int16": layout == "girp" or xt_s, "xmp_drone_dji": xmp,
            "exif_time": exif.get("DateTimeOriginal") or exif.get("DateTime"), "time_basis": time_basis}
    return [ImportedFrame(path=path, format="dji-rjpeg", layout=layout, pixels=pixels,
                          model=DjiModel(layout=layout, **_rounded(params)),
                          timestamp_ns=ts, sensor_model=f"DJI {model}".strip(),
                          sensor_id=f"DJI-{model or 'UNKNOWN'}"[:32],
                          vendor_metadata=meta, blobs=blobs)]
