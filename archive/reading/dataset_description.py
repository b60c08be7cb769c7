"""What a session's Dataset says about itself, written once for every way of opening it.

``thermcap.open(folder | bucket).to_xarray()`` builds its Dataset here in the process; the
server's Zarr store (formats 2 and 3) describes the same Dataset to ``xr.open_zarr``. Both take
their attributes and coordinate types from this module, so the local and the remote Dataset are
one Dataset: the same names, dtypes and attributes, each writable with ``to_netcdf`` (no
attribute is a dict or None).

CF 1.11: ``temperature`` is a ``surface_temperature`` (a radiometric camera measures the
surface it sees) with ``units_metadata``; every coordinate has its ``axis`` or ``long_name``.
"""

from __future__ import annotations

from typing import Any

from thermcap.archive.reading.frame_table import FRAME_FIELDS

__all__ = ["CONVENTIONS", "PIXEL_AXIS_DTYPE", "coordinate_attrs", "session_attrs", "variable_attrs"]

CONVENTIONS = "CF-1.11"
PIXEL_AXIS_DTYPE = "<i4"  # y and x: row and column numbers

_TEMPERATURE_COMMENT = ("from counts by the session's radiometric model (its latest version covering each frame, "
                        "unless a version was asked for); NaN: a pixel of the session's bad-pixel map")


def session_attrs(session_id: str, sensor: dict[str, Any] | None, frames_dropped: int | None,
                  named: dict[str, str]) -> dict[str, Any]:
    """The Dataset's global attributes. ``sensor`` is the session's sensor block (``model``,
    ``sensor_id``, ``frame_rate_hz``); ``named`` what ``models_named`` says of the model versions."""
    sensor = sensor or {}
    attrs: dict[str, Any] = {"Conventions": CONVENTIONS, "title": f"thermcap session {session_id}",
                             "source": "thermcap", "session_id": session_id,
                             "sensor": sensor.get("model"), "sensor_id": sensor.get("sensor_id"),
                             "fps": float(sensor["frame_rate_hz"]) if sensor.get("frame_rate_hz") else None,
                             "frames_dropped": int(frames_dropped or 0), **named}
    return {k: v for k, v in attrs.items() if v is not None}  # netCDF has no null attribute


def variable_attrs(name: str, model_version: str = "") -> dict[str, Any]:
    """Attributes of ``counts`` or ``temperature``."""
    if name == "counts":
        return {"long_name": "raw sensor counts", "units": "1"}
    if name == "temperature":
        return {"long_name": "temperature", "standard_name": "surface_temperature", "units": "degC",
                "units_metadata": "temperature: on_scale", "model_version": model_version,
                "comment": _TEMPERATURE_COMMENT}
    raise KeyError(name)


def coordinate_attrs(name: str) -> dict[str, Any]:
    """Attributes of a coordinate: ``time``, ``frame``, ``y``, ``x`` or a sidecar field."""
    if name == "time":
        return {"standard_name": "time", "axis": "T"}
    if name == "frame":
        return {"long_name": "frame number in the session"}
    if name == "y":
        return {"long_name": "row, 0 at the top", "axis": "Y"}
    if name == "x":
        return {"long_name": "column, 0 at the left", "axis": "X"}
    what = FRAME_FIELDS[name][2]
    return {"long_name": what, **({"units": "degC", "units_metadata": "temperature: on_scale"}
                                  if name.endswith("_c") else {})}
