"""ICD files: a 16-bit radiometric TIFF or a headerless Gray16 ``.raw``/``.gray16``, each with its
``.json`` sidecar (ICD 2.1, 2.2, 4.1). The sidecar's radiometric block becomes the model."""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from thermcap.recorder.icd.names import parse_name
from thermcap.recorder.icd.sidecar import validate_sidecar
from thermcap.recorder.importers.base import ImportedFrame, ImportFileError
from thermcap.recorder.radiometry import LinearModel, ScaledKelvinModel, model_from_dict

__all__ = ["iter_icd_tiff", "read_icd_raw", "read_icd_tiff", "sidecar_for"]


def sidecar_for(path: str) -> Path | None:
    p = Path(path).with_suffix(".json")
    return p if p.is_file() else None


def _sidecar(path: str, required: bool) -> dict | None:
    sc = sidecar_for(path)
    if sc is None:
        if required:
            raise ImportFileError(f"{path}: the ICD sidecar {Path(path).with_suffix('.json').name} is missing")
        return None
    try:
        doc = json.loads(sc.read_text())
    except ValueError as exc:
        raise ImportFileError(f"{sc}: not valid JSON ({exc})") from None
    try:
        validate_sidecar(doc)
    except Exception as exc:
        raise ImportFileError(f"{sc}: {exc}") from None
    return doc


def _model(doc: dict | None):
    if doc is None:
        return None
    rad = doc["radiometric"]
    if isinstance(rad.get("model"), dict):
        return model_from_dict(rad["model"])
    if rad.get("scale_factor_deg_c_per_count") is not None:
        return LinearModel(rad["scale_factor_deg_c_per_count"], rad["offset_deg_c"], rad.get("bit_depth", 14))
    return None


def _timestamp(path: str, doc: dict | None) -> int | None:
    from thermcap.recorder.icd.names import parse_rfc3339

    if doc and doc.get("capture", {}).get("timestamp"):
        try:
            return parse_rfc3339(doc["capture"]["timestamp"])
        except ValueError:
            pass
    try:
        return parse_name(Path(path).name).timestamp_ns
    except ValueError:
        return None


def read_icd_tiff(path: str, data: bytes) -> list[ImportedFrame]:
    return list(iter_icd_tiff(path, data))


def iter_icd_tiff(path: str, data: bytes) -> Iterator[ImportedFrame]:
    """Every frame of a 16-bit radiometric TIFF, one page at a time: a single image or a stack (a
    sequence as ResearchIR, flirpy or tifffile save one). The frames are the single-channel uint16
    full-resolution pages of the first such page's size; any other page (a reduced-resolution
    preview, the visual camera's colour page, a page of another size) is left out by name, in
    the first frame's ``vendor_metadata["pages_left_out"]``, never without a word."""
    doc = _sidecar(path, required=False)
    model = _model(doc)
    note = None
    if model is None:
        # No sidecar: the FLIR/flirpy radiometric-TIFF convention (T = counts*0.04 - 273.15),
        # said plainly in the metadata since nothing in the file states it.
        model = ScaledKelvinModel(counts_per_kelvin=25.0)
        note = "no ICD sidecar: FLIR radiometric TIFF convention 0.04 K/count assumed"
    sensor = (doc or {}).get("sensor", {})
    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            # every page, by its index in the file (a light TiffFrame, where tifffile gives one, as a page)
            pages = [p if isinstance(p, tifffile.TiffPage) else p.aspage() for p in tif.pages]
            gray = next((p for p in pages if not _not_gray16(p)), None)
            if gray is None:
                page = pages[0]
                raise ImportFileError(f"{path}: not a single-channel 16-bit TIFF "
                                      f"({page.dtype}, {page.samplesperpixel} samples)")
            shape = (gray.imagelength, gray.imagewidth)
            verdicts = [(i, p, _not_a_frame(p, shape)) for i, p in enumerate(pages)]
            left_out = [{"page": i, "why": why} for i, _, why in verdicts if why]
            frames = [(i, p) for i, p, why in verdicts if not why]
            for k, (i, page) in enumerate(frames):
                try:
                    pixels = page.asarray()
                except Exception as exc:
                    raise ImportFileError(f"{path}: page {i} of the TIFF is damaged ({type(exc).__name__}: {exc})") \
                        from None
                if pixels.ndim != 2 or pixels.shape != shape or pixels.size == 0:
                    raise ImportFileError(f"{path}: TIFF image data of page {i} is damaged (decoded {pixels.shape}, "
                                          f"header says {page.imagewidth}x{page.imagelength})")
                vendor: dict[str, Any] = {"sidecar": doc, "note": note}
                if len(frames) > 1:
                    vendor["page"] = i
                if k == 0 and left_out:
                    vendor["pages_left_out"] = left_out
                yield ImportedFrame(path=path, format="icd-tiff" if doc else "radiometric-tiff", layout=None,
                                    pixels=np.ascontiguousarray(pixels, dtype=np.uint16), model=model,
                                    timestamp_ns=_timestamp(path, doc),
                                    sensor_model=sensor.get("model", page.software or "TIFF"),
                                    sensor_id=_sensor_id(path, sensor), vendor_metadata=vendor, frame_index=k)
    except ImportFileError:
        raise
    except Exception as exc:
        raise ImportFileError(f"{path}: unreadable TIFF ({type(exc).__name__}: {exc})") from None


def _not_gray16(page: tifffile.TiffPage) -> str | None:
    """Why ``page`` cannot be a thermal frame at all, or None."""
    if page.is_reduced:
        return "a reduced-resolution preview"
    if page.dtype != np.uint16 or page.samplesperpixel != 1:
        return f"{page.samplesperpixel} sample(s) of {page.dtype} a pixel, not Gray16"
    return None


def _not_a_frame(page: tifffile.TiffPage, shape: tuple[int, int]) -> str | None:
    """Why ``page`` is not a frame of a stack of ``shape`` (rows, columns), or None."""
    if (why := _not_gray16(page)) is not None:
        return why
    if (page.imagelength, page.imagewidth) != shape:
        return f"{page.imagewidth}x{page.imagelength}, the frames {shape[1]}x{shape[0]}"
    return None


def read_icd_raw(path: str, data: bytes) -> list[ImportedFrame]:
    doc = _sidecar(path, required=True)
    assert doc is not None  # required: missing raises
    res = doc["sensor"]["resolution"]
    w, h = res["width"], res["height"]
    if len(data) != w * h * 2:
        raise ImportFileError(f"{path}: {len(data)} bytes, but the sidecar's {w}x{h} Gray16 frame needs {w * h * 2}")
    return [ImportedFrame(path=path, format="icd-raw", layout=None,
                          pixels=np.frombuffer(data, dtype="<u2").reshape(h, w).copy(),
                          model=_model(doc) or LinearModel(),
                          timestamp_ns=_timestamp(path, doc), sensor_model=doc["sensor"].get("model", "ICD"),
                          sensor_id=_sensor_id(path, doc["sensor"]), vendor_metadata={"sidecar": doc})]


def _sensor_id(path: str, sensor: dict) -> str:
    try:
        return parse_name(Path(path).name).sensor_id
    except ValueError:
        return "".join(c for c in str(sensor.get("model", "ICD")).upper() if c.isalnum())[:32] or "ICD"
