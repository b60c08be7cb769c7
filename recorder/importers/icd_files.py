"""ICD files: a 16-bit radiometric TIFF or a headerless Gray16 ``.raw``/``.gray16``, each with its
``.json`` sidecar (ICD 2.1, 2.2, 4.1). The sidecar's radiometric block becomes the model."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import tifffile

from thermcap.recorder.icd.names import parse_name
from thermcap.recorder.icd.sidecar import validate_sidecar
from thermcap.recorder.importers.base import ImportedFrame, ImportFileError
from thermcap.recorder.radiometry import LinearModel, ScaledKelvinModel, model_from_dict

__all__ = ["read_icd_raw", "read_icd_tiff", "sidecar_for"]


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
    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            page = tif.pages[0]
            assert isinstance(page, tifffile.TiffPage)  # the first page is always a full page
            if page.dtype != np.uint16 or page.samplesperpixel != 1:
                raise ImportFileError(f"{path}: not a single-channel 16-bit TIFF "
                                   f"({page.dtype}, {page.samplesperpixel} samples)")
            pixels = page.asarray()
            software = (page.software or "")
            if pixels.ndim != 2 or pixels.shape != (page.imagelength, page.imagewidth) or pixels.size == 0:
                raise ImportFileError(f"{path}: TIFF image data is damaged (decoded {pixels.shape}, "
                                   f"header says {page.imagewidth}x{page.imagelength})")
    except ImportFileError:
        raise
    except Exception as exc:
        raise ImportFileError(f"{path}: unreadable TIFF ({type(exc).__name__}: {exc})") from None
    doc = _sidecar(path, required=False)
    model = _model(doc)
    note = None
    if model is None:
        # No sidecar: the FLIR/flirpy radiometric-TIFF convention (T = counts*0.04 - 273.15),
        # said plainly in the metadata since nothing in the file states it.
        model = ScaledKelvinModel(counts_per_kelvin=25.0)
        note = "no ICD sidecar: FLIR radiometric TIFF convention 0.04 K/count assumed"
    sensor = (doc or {}).get("sensor", {})
    return [ImportedFrame(path=path, format="icd-tiff" if doc else "radiometric-tiff", layout=None,
                          pixels=np.ascontiguousarray(pixels, dtype=np.uint16), model=model,
                          timestamp_ns=_timestamp(path, doc), sensor_model=sensor.get("model", software or "TIFF"),
                          sensor_id=_sensor_id(path, sensor), vendor_metadata={"sidecar": doc, "note": note})]


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
