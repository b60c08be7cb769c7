"""FLIR radiometric JPEG (APP1 ``FLIR`` chunks), FFF, SEQ and CSQ (formats.md 3)."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

import imagecodecs
import numpy as np

from thermcap.recorder.importers.base import ImportedFrame, ImportFileError, TruncatedImageError, read_exact
from thermcap.recorder.importers.file_view import FileView
from thermcap.recorder.importers.jpeg import app_segments
from thermcap.recorder.radiometry import FlirPlanckModel

__all__ = ["flir_jpeg_payload", "iter_fff_records", "parse_fff", "read_fff_file", "read_flir_jpeg"]

RAW, CAMERA_INFO, GPS_INFO = 0x01, 0x20, 0x2B
#: What starts an FFF image: both magics occur in FLIR files.
_HEADERS = (b"FFF\x00", b"AFF\x00")
#: How much padding between two images is read at once, looking for the next header.
_GAP_WINDOW = 1 << 20


def flir_jpeg_payload(path: str, data: bytes) -> bytes | None:
    """The FFF inside a FLIR JPEG (APP1 chunks 'FLIR\\0', 0x01, index, last), or None."""
    chunks: dict[int, bytes] = {}
    last = None
    for marker, payload in app_segments(path, data):
        if marker == 0xE1 and payload[:5] == b"FLIR\x00" and len(payload) >= 8:
            chunks[payload[6]] = payload[8:]
            last = payload[7]
    if not chunks:
        return None
    if last is None:
        raise ImportFileError(f"{path}: FLIR APP1 chunks carry no chunk count (damaged file?)")
    missing = [i for i in range(last + 1) if i not in chunks] if last is not None else []
    if missing:
        raise ImportFileError(f"{path}: FLIR APP1 chunks {missing} of 0..{last} are missing (truncated file?)")
    return b"".join(chunks[i] for i in range(last + 1))


def _byteorder(path: str, fff: bytes) -> str:
    if fff[:4] not in _HEADERS:
        raise ImportFileError(f"{path}: not a FLIR FFF record (magic {fff[:4]!r})")
    for order in (">", "<"):
        (version,) = struct.unpack(order + "I", read_exact(path, fff, 0x14, 4, "FFF header"))
        if 100 <= version < 200:
            return order
    raise ImportFileError(f"{path}: FFF header version not in 100..199 in either byte order")


def parse_fff(path: str, fff: bytes) -> dict[int, tuple[int, bytes]]:
    """{record type: (subtype, bytes)} of one FFF image."""
    order = _byteorder(path, fff)
    dir_off, count = struct.unpack(order + "II", read_exact(path, fff, 0x18, 8, "FFF header"))
    if count > 10_000:
        raise ImportFileError(f"{path}: FFF directory claims {count} entries")
    records: dict[int, tuple[int, bytes]] = {}
    for i in range(count):
        e = read_exact(path, fff, dir_off + 32 * i, 32, "FFF directory")
        rtype, sub, _ver, _idx, off, length = struct.unpack(order + "HHIIII", e[:20])
        if rtype == 0:
            continue
        records.setdefault(rtype, (sub, read_exact(path, fff, off, length, f"FFF record 0x{rtype:02X}")))
    return records


def _rec_order(rec: bytes, default: str) -> str:
    (marker,) = struct.unpack(default + "H", rec[:2])
    return default if marker < 0x100 else ("<" if default == ">" else ">")


def _raw_frame(path: str, sub: int, rec: bytes, order: str) -> np.ndarray:
    o = _rec_order(rec, order)
    if len(rec) < 0x20:
        raise ImportFileError(f"{path}: FLIR raw record too short ({len(rec)} bytes)")
    _, w, h = struct.unpack(o + "HHH", rec[:6])
    body = rec[0x20:]
    if w == 0 or h == 0 or w * h > 50_000_000:
        raise ImportFileError(f"{path}: FLIR raw record has an impossible size {w}x{h}")
    if sub in (1, 2):
        if len(body) < w * h * 2:
            raise ImportFileError(f"{path}: FLIR raw data truncated: {len(body)} bytes for {w}x{h}x2")
        return np.frombuffer(body[: w * h * 2], dtype=">u2" if sub == 1 else "<u2").reshape(h, w).astype("<u2")
    try:
        if sub == 3:
            img = imagecodecs.png_decode(body)
            img = img.astype(np.uint16)
            img = ((img >> 8) | ((img & 0xFF) << 8)).astype(np.uint16)  # FLIR PNGs are byte-swapped
        elif sub == 4:
            img = imagecodecs.jpegls_decode(body).astype(np.uint16)
        else:
            raise ImportFileError(f"{path}: unknown FLIR raw data subtype {sub}")
    except ImportFileError:
        raise
    except Exception as exc:
        raise ImportFileError(f"{path}: FLIR raw image does not decode ({type(exc).__name__}: {exc})") from exc
    if img.shape != (h, w):
        raise ImportFileError(f"{path}: FLIR raw image is {img.shape[1]}x{img.shape[0]}, header says {w}x{h}")
    return img


def _f(rec: bytes, o: str, off: int) -> float:
    return struct.unpack(o + "f", rec[off:off + 4])[0]


def _camera_info(path: str, rec: bytes, order: str) -> tuple[FlirPlanckModel, dict]:
    if len(rec) < 0x310:
        raise ImportFileError(f"{path}: FLIR CameraInfo record too short ({len(rec)} bytes)")
    o = _rec_order(rec, order)
    k = 273.15
    rh = _f(rec, o, 0x3C)
    model = FlirPlanckModel(
        planck_r1=_f(rec, o, 0x58), planck_b=_f(rec, o, 0x5C), planck_f=_f(rec, o, 0x60),
        planck_o=float(struct.unpack(o + "i", rec[0x308:0x30C])[0]), planck_r2=_f(rec, o, 0x30C),
        emissivity=_f(rec, o, 0x20), object_distance_m=_f(rec, o, 0x24), reflected_temp_c=_f(rec, o, 0x28) - k,
        atmospheric_temp_c=_f(rec, o, 0x2C) - k, ir_window_temp_c=_f(rec, o, 0x30) - k,
        ir_window_transmission=_f(rec, o, 0x34), relative_humidity_pct=rh * 100 if rh <= 2 else rh,
        alpha1=_f(rec, o, 0x70), alpha2=_f(rec, o, 0x74), beta1=_f(rec, o, 0x78), beta2=_f(rec, o, 0x7C),
        trans_x=_f(rec, o, 0x80))
    text = lambda a, b: rec[a:b].split(b"\x00")[0].decode("latin-1").strip()  # noqa: E731
    meta: dict[str, Any] = {
            "camera_model": text(0xD4, 0xF4), "part_number": text(0xF4, 0x104), "serial": text(0x104, 0x114),
            "lens_model": text(0x170, 0x180),
            # the calibrated measurement range (CameraTemperatureRangeMin/Max, Kelvin floats)
            "camera_range_c": [round(_f(rec, o, 0x94) - k, 3), round(_f(rec, o, 0x90) - k, 3)]}
    fov = _f(rec, o, 0x1B4)  # FieldOfView (ExifTool's FLIR CameraInfo 0x1b4), degrees; 0 where unset
    if 0 < fov < 180:
        meta["field_of_view_deg"] = round(fov, 4)
    if model.emissivity <= 0 or model.planck_r1 == 0:
        raise ImportFileError(f"{path}: FLIR CameraInfo has no usable Planck constants")
    if len(rec) >= 0x38E:  # DateTimeOriginal: u32 UTC seconds, u32 ms (low 16 bits), s16 minutes west of UTC
        seconds, millis, west = struct.unpack(o + "IIh", rec[0x384:0x38E])
        if 946684800 <= seconds < 4102444800:  # 2000..2100: anything else is an unset clock
            meta["capture_time_ns"] = seconds * 1_000_000_000 + (millis & 0xFFFF) * 1_000_000
            meta["capture_utc_offset_min"] = -west
    return model, meta


def _gps_info(rec: bytes, order: str) -> dict | None:
    """FLIR's GPSInfo record (ExifTool's FLIR GPSInfo table): valid flag, signed decimal degrees
    as doubles, altitude as a float, the map datum; None when the camera had no fix."""
    if len(rec) < 0x68:
        return None
    o = _rec_order(rec, order)
    (valid,) = struct.unpack(o + "I", rec[:4])
    if valid != 1:
        return None
    lat, lon = struct.unpack(o + "dd", rec[0x10:0x20])
    (alt,) = struct.unpack(o + "f", rec[0x20:0x24])
    ref_lat, ref_lon = rec[0x08:0x09].decode("latin-1"), rec[0x0A:0x0B].decode("latin-1")
    lat = -abs(lat) if ref_lat == "S" else abs(lat) if ref_lat == "N" else lat
    lon = -abs(lon) if ref_lon == "W" else abs(lon) if ref_lon == "E" else lon
    if not (-90 <= lat <= 90 and -180 <= lon <= 180) or (lat == 0 and lon == 0):
        return None
    datum = rec[0x58:0x68].split(b"\x00")[0].decode("latin-1").strip() or "WGS84"
    return {"latitude": lat, "longitude": lon, "altitude_m": round(float(alt), 3), "datum": datum,
            "source": "FLIR GPSInfo"}


def flir_sensor_id(camera_model: str) -> str:
    """The camera model as an ICD-safe sensor id: 'FLIR T640' -> 'FLIR-T640', 'Duo Pro R' ->
    'FLIR-Duo-Pro-R' (no '_', which separates the parts of an ICD file name)."""
    import re

    name = camera_model if camera_model.upper().startswith("FLIR") else f"FLIR {camera_model}"
    return re.sub(r"[^A-Za-z0-9-]+", "-", name).strip("-")[:32] or "FLIR"


def frame_from_fff(path: str, fff: bytes, fmt: str, index: int = 0) -> ImportedFrame:
    order = _byteorder(path, fff)
    records = parse_fff(path, fff)
    if RAW not in records:
        raise ImportFileError(f"{path}: FLIR file has no raw thermal data record")
    if CAMERA_INFO not in records:
        raise ImportFileError(f"{path}: FLIR file has no CameraInfo record (no Planck constants)")
    sub, raw = records[RAW]
    pixels = _raw_frame(path, sub, raw, order)
    model, meta = _camera_info(path, records[CAMERA_INFO][1], order)
    creator = fff[4:20].split(b"\x00")[0].decode("latin-1")
    meta.update(creator=creator, byte_order="big" if order == ">" else "little", raw_subtype=sub)
    gps = _gps_info(records[GPS_INFO][1], order) if GPS_INFO in records else None
    if gps is not None:
        meta["gps"] = gps
    stamp = meta.pop("capture_time_ns", None)
    if stamp is not None:
        meta["time_basis"] = "utc: FLIR CameraInfo DateTimeOriginal"
    return ImportedFrame(path=path, format=fmt, layout={1: "raw-be", 2: "raw-le", 3: "png", 4: "jpeg-ls"}.get(sub),
                         pixels=np.ascontiguousarray(pixels, dtype=np.uint16), model=model, timestamp_ns=stamp,
                         sensor_model=meta["camera_model"] or creator or "FLIR",
                         sensor_id=flir_sensor_id(meta["camera_model"]) if meta["camera_model"] else "FLIR",
                         vendor_metadata=meta, frame_index=index,
                         blobs={"flir_camera_info.bin": records[CAMERA_INFO][1]})


def read_flir_jpeg(path: str, data: bytes) -> list[ImportedFrame]:
    from thermcap.recorder.importers.exif import capture_time, exif_fields, exif_position, xmp_fields

    fff = flir_jpeg_payload(path, data)
    if fff is None:
        raise ImportFileError(f"{path}: a JPEG with no FLIR thermal data")
    frame = frame_from_fff(path, fff, "flir-rjpeg")
    app1 = [p for m, p in app_segments(path, data) if m == 0xE1]
    exif = exif_fields(app1)
    xmp = xmp_fields(app1)
    ts, time_basis = capture_time(exif, xmp)
    if frame.timestamp_ns is None or time_basis.startswith("utc: drone-dji"):
        # FLIR's own UTC time with milliseconds beats EXIF's zone-less local time; DJI's XMP UTC
        # (a Zenmuse XT2) is as good and is the drone's clock
        frame.timestamp_ns = ts
        frame.vendor_metadata["time_basis"] = time_basis
    frame.vendor_metadata.update(exif_make=exif.get("Make"), exif_model=exif.get("Model"),
                                 exif_focal_length_mm=exif.get("FocalLength"),
                                 exif_focal_length_35mm=exif.get("FocalLengthIn35mmFilm"),
                                 exif_time=exif.get("DateTimeOriginal") or exif.get("DateTime"))
    if xmp:
        frame.vendor_metadata["xmp_drone_dji"] = xmp
    for key, prefix in (("xmp_camera", "Camera"), ("xmp_flir", "FLIR")):  # a FLIR drone camera's pose
        fields = xmp_fields(app1, prefix)
        if fields:
            frame.vendor_metadata[key] = fields
    if "gps" not in frame.vendor_metadata:  # FLIR's own record first, EXIF's GPS where that is absent
        position = exif_position(exif)
        if position is not None:
            frame.vendor_metadata["gps"] = position
    return [frame]


def _short_trailer(path: str, image: bytes, order: str, dir_off: int, count: int) -> tuple[bytes, str] | None:
    """An image whose directory promises more bytes than the file holds: the image as it can be
    read (records past the end dropped, the raw record cut to what is there), and a note saying
    so; None when what is missing is the camera's calibration or the directory itself. Whether
    the raw image is complete is for its decoder to say: ``frame_from_fff`` refuses a cut one."""
    have = len(image)
    if dir_off + 32 * count > have:
        return None
    buf = bytearray(image)
    dropped, cut = [], 0
    for i in range(count):
        at = dir_off + 32 * i
        rtype, _sub, _ver, _id, off, length = struct.unpack(order + "HHIIII", buf[at:at + 20])
        if not rtype or off + length <= have:
            continue
        if rtype == RAW and off + 0x20 < have:
            cut = off + length - have
            buf[at + 16:at + 20] = struct.pack(order + "I", have - off)
        elif rtype in (CAMERA_INFO, RAW):
            return None
        else:
            dropped.append(f"0x{rtype:02X}")
            buf[at:at + 2] = struct.pack(order + "H", 0)
    missing = max(cut, 0)
    note = (f"the image's directory promises {missing or 'some'} bytes more than the file holds; the image was "
            f"complete and kept" + (f"; records {', '.join(dropped)} past the end were left out" if dropped else ""))
    return bytes(buf), note


def iter_fff_records(path: str, data: bytes | FileView,
                     notes: dict[int, tuple[str, int, int, int]] | None = None,
                     skipped: dict[int, dict[str, Any]] | None = None) -> Iterator[bytes]:
    """SEQ/CSQ: FFF images back to back. Walk header to header by each image's extent (the
    largest record end); 'FFF\\0' inside pixel data is never mistaken for a header. Only each
    image's bytes (and a gap's) are ever read (``data`` may be a ``FileView`` of a multi-GB file).

    The last image may end a few bytes short of what its directory promises (a trailer cut, or
    padding a writer never wrote) while its image stream is whole: it is kept, and ``notes``
    says so by image index (with where it starts, the bytes there and the bytes promised); only
    an image whose pixels are cut is truncated.

    Bytes between two images that start no header are skipped to the next header, and
    ``skipped`` says so by the index of the image after them (where they start, how many, and
    whether they are all zero: bytes that are not may be an image whose header is damaged);
    bytes after the last image, by the index one past it."""
    pos, n = 0, len(data)
    index = 0
    while pos + 0x40 <= n:
        order = _byteorder(path, data[pos:pos + 0x40])
        dir_off, count = struct.unpack(order + "II", data[pos + 0x18:pos + 0x20])
        end = dir_off + 32 * count
        if pos + end > n:
            raise TruncatedImageError(path, index, pos, n - pos, end)
        for i in range(count):
            rtype, _s, _v, _i, off, length = struct.unpack(order + "HHIIII", data[pos + dir_off + 32 * i:
                                                                                    pos + dir_off + 32 * i + 20])
            if rtype:
                end = max(end, off + length)
        if pos + end > n:
            kept = _short_trailer(path, bytes(data[pos:n]), order, dir_off, count) if notes is not None else None
            if kept is None or notes is None:
                raise TruncatedImageError(path, index, pos, n - pos, end)
            notes[index] = (kept[1], pos, n - pos, end)
            yield kept[0]
            return
        yield bytes(data[pos:pos + end])
        index += 1
        pos += end
        if pos < n and data[pos:pos + 4] not in _HEADERS:  # padding between images, or after the last
            gap = pos
            pos, all_zero = _next_header(data, pos, n)
            if skipped is not None:
                skipped[index] = {"byte": gap, "bytes": pos - gap, "all_zero": all_zero}
    if skipped is not None and pos < n:
        # A header's magic too close to the end for a whole header: after the last image too, and
        # never all zero, since the magic is in it.
        start = skipped[index]["byte"] if index in skipped else pos
        skipped[index] = {"byte": start, "bytes": n - start, "all_zero": False}


def _next_header(data: bytes | FileView, pos: int, n: int) -> tuple[int, bool]:
    """Where the nearest header of either kind starts at or after ``pos`` (``n`` if none), and
    whether the bytes before it are all zero, in one read of them. The padding is scanned a
    window at a time, so a gap costs what it holds, not the rest of the file (searching a
    multi-GB SEQ to its end for the rarer magic at every gap would)."""
    all_zero = True
    while pos < n:
        window = data[pos:min(n, pos + _GAP_WINDOW + 3)]  # 3: a header across two windows
        found = [at for at in (window.find(h) for h in _HEADERS) if at >= 0]
        gap = min(found) if found else min(len(window), _GAP_WINDOW)
        all_zero = all_zero and window.count(0, 0, gap) == gap
        if found:
            return pos + gap, all_zero
        pos += _GAP_WINDOW
    return n, all_zero


def read_fff_file(path: str, data: bytes) -> list[ImportedFrame]:
    return list(iter_fff_file(path, data))


def iter_fff_file(path: str, data: bytes | FileView) -> Iterator[ImportedFrame]:
    """An FFF, SEQ or CSQ file's frames one at a time (``data`` may be a ``FileView``): a long SEQ never
    sits decoded in memory. A file with a second image is a SEQ (CSQ when JPEG-LS coded)."""
    notes: dict[int, tuple[str, int, int, int]] = {}
    skipped: dict[int, dict[str, Any]] = {}
    records = iter_fff_records(path, data, notes, skipped)
    first = next(records, None)
    if first is None:
        raise ImportFileError(f"{path}: no FFF image in the file")

    def named(rec: bytes, i: int, multi: bool) -> ImportedFrame:
        try:
            frame = frame_from_fff(path, rec, "flir-fff", i)
        except ImportFileError as exc:
            if i in notes:  # the short image's pixels are cut after all: truncated, as any cut image
                raise TruncatedImageError(path, i, *notes[i][1:]) from exc
            raise
        if multi:
            frame.format = "flir-seq" if frame.layout != "jpeg-ls" else "flir-csq"
        if i in notes:
            frame.vendor_metadata["short_trailer"] = notes[i][0]
        if i in skipped:  # what the walk left out before this image, kept with it (never silently)
            frame.vendor_metadata["skipped_before"] = skipped[i]
        return frame

    # Each image is handed on once the walk has looked past it: whether the file is a sequence,
    # and what follows the last image, are known then. A complete image is handed on before the
    # error of the one after it (a second image cut short had taken the first with it).
    held: tuple[bytes, int] = (first, 0)
    multi: bool | None = None
    while True:
        try:
            rec = next(records, None)
        except Exception:
            yield named(*held, multi=True)  # a second image began, cut or damaged: a sequence
            raise
        multi = (rec is not None) if multi is None else multi
        if rec is None:
            break
        yield named(*held, multi=multi)
        held = (rec, held[1] + 1)
    last = named(*held, multi=bool(multi))
    if held[1] + 1 in skipped:  # bytes after the last image
        last.vendor_metadata["skipped_after"] = skipped[held[1] + 1]
    yield last
