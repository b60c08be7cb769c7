"""TERRA-REF gantry FLIR A615 ``<uuid>_ir.bin`` + ``<uuid>_metadata.json`` (formats.md 2).

The frame is stored as it is in the file (480 rows x 640 columns); the pipeline's ``rot90`` is a
display choice and is recorded, not applied. ``is calibrated == "True"`` means deci-kelvin
counts; otherwise the Planck model with the file's constants, in the pipeline's own form by
default (what every published TERRA-REF product used), with the physical inversion available.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from thermcap.recorder.importers.base import ImportedFrame, ImportFileError
from thermcap.recorder.radiometry import RadiometricModel, ScaledKelvinModel, TerraRefPlanckModel

__all__ = ["metadata_for", "read_terraref"]

ROWS, COLS = 480, 640


def metadata_for(path: str) -> Path | None:
    p = Path(path)
    if not p.name.endswith("_ir.bin"):
        return None
    meta = p.with_name(p.name[: -len("_ir.bin")] + "_metadata.json")
    return meta if meta.is_file() else None


def _num(d: dict, key: str, path: str) -> float:
    try:
        return float(d[key])
    except (KeyError, TypeError, ValueError):
        raise ImportFileError(f"{path}: metadata field {key!r} is missing or not a number") from None


def read_terraref(path: str, data: bytes, *, variant: str = "pipeline") -> list[ImportedFrame]:
    if len(data) != ROWS * COLS * 2:
        raise ImportFileError(f"{path}: a TERRA-REF _ir.bin is {ROWS}x{COLS}x2 = {ROWS * COLS * 2} bytes, "
                           f"this one is {len(data)}")
    meta_path = metadata_for(path)
    if meta_path is None:
        raise ImportFileError(f"{path}: the TERRA-REF metadata file <uuid>_metadata.json is missing beside it")
    try:
        meta = json.loads(meta_path.read_text())["lemnatec_measurement_metadata"]
    except (ValueError, KeyError) as exc:
        raise ImportFileError(f"{meta_path}: not a LemnaTec metadata file ({exc})") from None
    fixed = meta.get("sensor_fixed_metadata", {})
    var = meta.get("sensor_variable_metadata", {})
    gantry = meta.get("gantry_system_variable_metadata", {})
    model: RadiometricModel
    if str(fixed.get("is calibrated", "False")).strip().lower() == "true":
        model = ScaledKelvinModel(counts_per_kelvin=10.0)
    else:
        model = TerraRefPlanckModel(
            r=_num(fixed, "calibration R", path), b=_num(fixed, "calibration B", path),
                                    f=_num(fixed, "calibration F", path),
            j0=_num(fixed, "calibration J0", path), j1=_num(fixed, "calibration J1", path),
            alpha1=_num(fixed, "calibration alpha1", path), alpha2=_num(fixed, "calibration alpha2", path),
            beta1=_num(fixed, "calibration beta1", path), beta2=_num(fixed, "calibration beta2", path),
            x=_num(fixed, "calibration X", path), variant=variant)
    ts = None
    if gantry.get("time"):
        try:
            ts = int(datetime.strptime(gantry["time"], "%m/%d/%Y %H:%M:%S").replace(tzinfo=UTC).timestamp()) * 10**9
        except ValueError:
            ts = None
    pixels = np.frombuffer(data, dtype="<u2").reshape(ROWS, COLS).copy()
    vendor = {"gantry_time": gantry.get("time"), "position_m": {k: gantry.get(f"position {k} [m]") for k in "xyz"},
              "speed_m_s": {k: gantry.get(f"speed {k} [m/s]") for k in "xyz"},
              "shutter_temperature_k": var.get("shutter temperature [K]"),
              "lens_temperature_k": var.get("lens temperature [K]"),
              "is_calibrated": fixed.get("is calibrated"),
              "display_rotation": "numpy.rot90(raw, 3) in the TERRA-REF pipeline",
              "camera_box_m": {k: fixed.get(f"location in camera box {k} [m]") for k in "xyz"},
              "field_of_view_m": {k: fixed.get(f"field of view {k} [m]") for k in "xy"},
              "temperature_variant": variant if isinstance(model, TerraRefPlanckModel) else "deci-kelvin"}
    return [ImportedFrame(path=path, format="terraref-bin", layout="480x640-le", pixels=pixels, model=model,
                          timestamp_ns=ts, sensor_model=f"FLIR {fixed.get('sensor product name', 'A615')}",
                          sensor_id="A615", vendor_metadata=vendor,
                          blobs={"terraref_metadata.json": meta_path.read_bytes()})]
