"""The per-frame JSON sidecar of ICD section 4.2, as a JSON Schema, with validation and a builder.

Every sidecar thermcap writes is validated against ``SIDECAR_SCHEMA``, compiled once with
jsonschema-rs (Rust): about 3.5 us for a frame's blocks with three targets, where fastjsonschema's
generated Python took 15 us, a sixth of the recorder's own Python per frame at 320x256. Values
jsonschema-rs does not take (numpy scalars, keys that are not strings) are checked by
fastjsonschema, as they always were. The same schema is the MCAP channel schema of
``/thermal/metadata``, so any reader can check it too.

The ICD's mandatory blocks are required. Values the ICD leaves undefined for a frame (the
contrast metrics of a frame with no target) are ``null`` rather than invented numbers, and
``thermal_analysis.source`` says where the analysis came from (``ground_truth``, ``detector``,
``skipped`` when the analysis worker fell behind, ``none``). Extra fields are allowed, as the
ICD is a floor, not a ceiling.
"""

from __future__ import annotations

import json
import math
from contextlib import suppress
from typing import Any

import fastjsonschema
import jsonschema_rs

from thermcap.recorder.exceptions import SidecarError
from thermcap.recorder.icd.names import FORMAT_VERSION

__all__ = ["SIDECAR_SCHEMA", "SidecarEncoder", "dumps_sidecar", "sidecar_schema_bytes", "validate_sidecar"]

_num = {"type": "number"}
_nnum = {"type": ["number", "null"]}
_bool = {"type": "boolean"}
_str = {"type": "string"}


def _obj(props: dict[str, Any], required: list[str] | None = None) -> dict[str, Any]:
    return {"type": "object", "properties": props, "required": required if required is not None else list(props)}


SIDECAR_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://thermcap.dev/schemas/thermal-sidecar-1.0.json",
    "title": "thermcap.ThermalSidecar",
    "description": "Per-frame radiometric thermal metadata (Thermal Data ICD 1.0, section 4.2)",
    **_obj(
        {
            "format_version": {"const": FORMAT_VERSION},
            "sensor": _obj(
                {
                    "model": _str,
                    "type": _str,
                    "serial_number": _str,
                    "spectral_range_um": {"type": "array", "items": _num, "minItems": 2, "maxItems": 2},
                    "resolution": _obj(
                        {"width": {"type": "integer", "minimum": 1}, "height": {"type": "integer", "minimum": 1}}
                    ),
                    "pixel_pitch_um": {"type": "number", "exclusiveMinimum": 0},
                    "netd_mk": {"type": "number", "minimum": 0},
                    "frame_rate_hz": {"type": "number", "exclusiveMinimum": 0},
                },
                ["model", "resolution"],
            ),
            "radiometric": _obj(
                {
                    "bit_depth": {"type": "integer", "minimum": 1, "maximum": 16},
                    "scale_factor_deg_c_per_count": _nnum,
                    "offset_deg_c": _nnum,
                    "scene_temp_min_deg_c": _nnum,
                    "scene_temp_max_deg_c": _nnum,
                    "calibration_date": {"type": ["string", "null"]},
                    "calibration_method": {"type": ["string", "null"]},
                    "model": {"type": "object", "required": ["kind"]},
                },
                ["bit_depth", "scale_factor_deg_c_per_count", "offset_deg_c"],
            ),
            "capture": _obj(
                {
                    "timestamp": {"type": "string", "pattern": r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d{1,9})?Z$"},
                    "frame_index": {"type": "integer", "minimum": 0},
                    "exposure_time_us": _nnum,
                    "gain_db": _nnum,
                    "fpa_temperature_c": _nnum,
                    "lens_focal_length_mm": _nnum,
                    "f_number": _nnum,
                },
                ["timestamp"],
            ),
            "environment": _obj(
                {
                    "ambient_temp_c": _nnum,
                    "humidity_percent": {"type": ["number", "null"], "minimum": 0, "maximum": 100},
                    "atmospheric_transmission": {"type": ["number", "null"], "minimum": 0, "maximum": 1},
                    "weather_condition": {"type": ["string", "null"]},
                    "visibility_m": _nnum,
                },
                [],
            ),
            "thermal_analysis": _obj(
                {
                    "thermal_contrast_grade": {"type": "number", "minimum": 0, "maximum": 1},
                    "max_target_temp_c": _nnum,
                    "min_background_temp_c": _nnum,
                    "delta_t_deg_c": _nnum,
                    "snr_db": _nnum,
                    "detection_confidence": {"type": ["number", "null"], "minimum": 0, "maximum": 1},
                    "source": {"enum": ["ground_truth", "detector", "skipped", "none"]},
                    # present only when the detector's worst-case bound cut its work short
                    "detection_capped": {"type": "object"},
                },
                ["thermal_contrast_grade", "max_target_temp_c", "min_background_temp_c", "delta_t_deg_c",
                 "snr_db", "detection_confidence"],
            ),
            "slew_to_cue": _obj(
                {
                    "slew_to_cue_active": _bool,
                    "radar_cue_received": _bool,
                    "radar_azimuth_deg": _nnum,
                    "radar_elevation_deg": _nnum,
                    "radar_range_m": _nnum,
                    "turret_pan_deg": _nnum,
                    "turret_tilt_deg": _nnum,
                    "search_pattern_active": _bool,
                    "state": {"enum": ["idle", "cue", "slew", "search", "lock", "handoff"]},
                },
                ["slew_to_cue_active", "radar_cue_received", "radar_azimuth_deg", "radar_elevation_deg",
                 "radar_range_m", "turret_pan_deg", "turret_tilt_deg", "search_pattern_active"],
            ),
            "targets": {
                "type": "array",
                "items": _obj(
                    {
                        "target_id": _str,
                        "bbox": {"type": "array", "items": {"type": "integer"}, "minItems": 4, "maxItems": 4},
                        "centroid": {"type": "array", "items": _num, "minItems": 2, "maxItems": 2},
                        "max_temp_c": _num,
                        "mean_temp_c": _num,
                        "classification": _str,
                        "confidence": {"type": "number", "minimum": 0, "maximum": 1},
                    }
                ),
            },
        },
        ["format_version", "sensor", "radiometric", "capture", "environment", "thermal_analysis",
         "slew_to_cue", "targets"],
    ),
}

class _Validator:
    """One schema, raising SidecarError with the offending field's path (``targets[1].confidence``)."""

    def __init__(self, schema: dict[str, Any]) -> None:
        self._schema = schema
        self._rs = jsonschema_rs.validator_for(schema)
        self._py: Any = None  # fastjsonschema's, compiled when first needed

    def __call__(self, value: Any) -> None:
        try:
            self._rs.validate(value)
            return
        except jsonschema_rs.ValidationError as exc:
            raise _error(exc, value) from exc
        except ValueError:  # a value jsonschema-rs does not take ("Unsupported type: 'float64'")
            pass
        if self._py is None:
            self._py = fastjsonschema.compile(self._schema)
        try:
            self._py(value)
        except fastjsonschema.JsonSchemaValueException as exc:
            field = (exc.name or "data").removeprefix("data").lstrip(".") or "<root>"
            raise SidecarError(field, exc.message.replace(exc.name or "data", "value")) from exc


def _error(exc: Any, value: Any) -> SidecarError:
    """jsonschema-rs's error as fastjsonschema's path of the field (``targets[1].confidence``),
    so messages and logs read as they always did; a missing field is named itself."""
    path = list(exc.instance_path)
    missing = getattr(exc.kind, "property", None)  # only a "required" error names a property
    if isinstance(missing, str):
        path.append(missing)
    field = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".") or "<root>"
    if isinstance(missing, str):
        return SidecarError(field, "is required")
    node = value
    with suppress(LookupError, TypeError):
        for p in path:
            node = node[p]
    if isinstance(node, float) and not math.isfinite(node):  # jsonschema-rs takes NaN and inf for null
        if '"number"' in exc.message:
            return SidecarError(field, "must be a finite number")
        return SidecarError(field, exc.message.replace("null", repr(node), 1))
    return SidecarError(field, exc.message)


_validate = _Validator(SIDECAR_SCHEMA)

#: Compact JSON without NaN, made once (``json.dumps`` with options builds an encoder a call),
#: and without circular-reference bookkeeping (3 of the 14 us a frame's blocks took): a circular
#: document ends in RecursionError instead, which ``_serialise`` reports.
_json = json.JSONEncoder(separators=(",", ":"), allow_nan=False, check_circular=False).encode


def _serialise(doc: dict[str, Any]) -> str:
    """JSON has no NaN or Infinity (Python would write them anyway and break every other reader),
    so a non-finite number is a SidecarError, naming its field; so is a document that contains itself."""
    try:
        return _json(doc)
    except ValueError as exc:
        raise SidecarError(_find_non_finite(doc, "") or "<root>", "must be a finite number") from exc
    except RecursionError as exc:
        raise SidecarError("<root>", "contains itself (or is nested too deeply to write)") from exc


def validate_sidecar(sidecar: dict[str, Any]) -> dict[str, Any]:
    """Raise SidecarError naming the offending field (e.g. ``sensor.resolution.width``)."""
    _validate(sidecar)
    return sidecar


class SidecarEncoder:
    """Validates and serialises a session's sidecars at recording speed.

    The ``sensor`` and ``radiometric`` blocks are the same for every frame of a session, so they
    are validated once here; each frame then validates only its own blocks (against the same
    schema's sub-schemas) instead of the whole document: half the cost, the same guarantee.
    """

    _PER_FRAME = ("capture", "environment", "thermal_analysis", "slew_to_cue", "targets")
    #: the per-frame blocks of ``SIDECAR_SCHEMA``, all required, as one schema
    _blocks = _Validator({"type": "object", "properties": {k: SIDECAR_SCHEMA["properties"][k] for k in _PER_FRAME},
                          "required": list(_PER_FRAME)})

    def __init__(self, sensor: dict[str, Any], radiometric: dict[str, Any]) -> None:
        probe = {"format_version": FORMAT_VERSION, "sensor": sensor, "radiometric": radiometric,
                 "capture": {"timestamp": "2000-01-01T00:00:00Z"}, "environment": {},
                 "thermal_analysis": {k: None for k in SIDECAR_SCHEMA["properties"]["thermal_analysis"]["required"]}
                 | {"thermal_contrast_grade": 0.0},
                 "slew_to_cue": {k: None for k in SIDECAR_SCHEMA["properties"]["slew_to_cue"]["required"]}
                 | {"slew_to_cue_active": False, "radar_cue_received": False, "search_pattern_active": False},
                 "targets": []}
        validate_sidecar(probe)
        self.sensor = sensor
        self.radiometric = radiometric
        # Serialised once: these bytes open every sidecar of the session.
        self._head = json.dumps({"format_version": FORMAT_VERSION, "sensor": sensor, "radiometric": radiometric},
                                separators=(",", ":"), allow_nan=False)[:-1]

    def encode(self, blocks: dict[str, Any]) -> bytes:
        """``blocks`` holds the per-frame keys; returns the complete validated sidecar as JSON bytes."""
        self._blocks(blocks)
        tail = _serialise({k: blocks[k] for k in self._PER_FRAME})
        return (self._head + "," + tail[1:]).encode()


def dumps_sidecar(sidecar: dict[str, Any]) -> bytes:
    """Validate and serialise; compact separators keep 60 sidecars a second small."""
    validate_sidecar(sidecar)
    return _serialise(sidecar).encode()


def _find_non_finite(value: Any, path: str) -> str | None:
    if isinstance(value, float) and not math.isfinite(value):
        return path
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        where = f"{path}.{k}" if isinstance(k, str) and path else (k if isinstance(k, str) else f"{path}[{k}]")
        found = _find_non_finite(v, where)
        if found:
            return found
    return None


def sidecar_schema_bytes() -> bytes:
    return json.dumps(SIDECAR_SCHEMA, indent=1).encode()
