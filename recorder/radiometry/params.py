"""Object parameters changed after capture, without touching the stored counts.

The camera guessed emissivity, reflected temperature, distance, atmosphere and window when it
recorded; a thermographer corrects them afterwards. ``reparameterise`` gives a new model with
them changed, under one set of names whatever the model calls them. A session keeps each change
as a numbered version (``radiometry.json``: who, when, why, which frames), and every
temperature names the version it used; version 0 is the model as recorded.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any

from thermcap.recorder.radiometry.base import RadiometricModel
from thermcap.recorder.storage.layout import RADIOMETRY_JSON

__all__ = [
    "OBJECT_PARAMS",
    "ModelVersion",
    "add_version",
    "model_for_frame",
    "models_named",
    "read_versions",
    "reparameterise",
    "versions_from",
]

OBJECT_PARAMS = ("emissivity", "reflected_temp_c", "object_distance_m", "atmospheric_temp_c",
                 "relative_humidity_pct", "ir_window_temp_c", "ir_window_transmission")

# our names -> (model field, scale into the field's units)
_FIELDS: dict[str, dict[str, tuple[str, float]]] = {
    "flir_planck": {"emissivity": ("emissivity", 1), "reflected_temp_c": ("reflected_temp_c", 1),
                    "object_distance_m": ("object_distance_m", 1), "atmospheric_temp_c": ("atmospheric_temp_c", 1),
                    "relative_humidity_pct": ("relative_humidity_pct", 1), "ir_window_temp_c": ("ir_window_temp_c", 1),
                    "ir_window_transmission": ("ir_window_transmission", 1)},
    "terraref_planck": {"emissivity": ("emissivity", 1), "object_distance_m": ("distance_m", 1),
                        "atmospheric_temp_c": ("atm_temp_c", 1), "relative_humidity_pct": ("humidity", 0.01)},
}
_LIMITS = {"emissivity": (0.01, 1.0), "ir_window_transmission": (0.01, 1.0), "relative_humidity_pct": (0.0, 100.0),
           "object_distance_m": (0.0, 1e5), "reflected_temp_c": (-273.15, 3000.0),
           "atmospheric_temp_c": (-273.15, 3000.0), "ir_window_temp_c": (-273.15, 3000.0)}


def reparameterise(model: RadiometricModel, params: dict[str, float]) -> RadiometricModel:
    """The model with these object parameters; ValueError names what this model cannot take."""
    kind = getattr(model, "kind", type(model).__name__)
    fields = _FIELDS.get(kind)
    if fields is None:
        why = ("DJI's curves live in DJI's SDK: `thermcap radiometry SESSION --set ... --dji-sdk` (or the API with "
               "THERMCAP_DJI_SDK set) measures the frames again at the new parameters") \
            if kind in ("dji", "lookup_table") else "it has no object parameters"
        raise ValueError(f"a {kind} model cannot be re-parameterised: {why}")
    changes = {}
    for name, value in params.items():
        if name not in OBJECT_PARAMS:
            raise ValueError(f"unknown object parameter {name!r}; use {', '.join(OBJECT_PARAMS)}")
        if name not in fields:
            raise ValueError(f"a {kind} model has no {name} (it takes {', '.join(fields)})")
        lo, hi = _LIMITS[name]
        v = float(value)
        if not lo <= v <= hi:
            raise ValueError(f"{name} = {v:g} is outside {lo:g}..{hi:g}")
        field, scale = fields[name]
        changes[field] = v * scale
    return dataclasses.replace(model, **changes)  # type: ignore[type-var]


@dataclasses.dataclass(frozen=True)
class ModelVersion:
    version: int
    at: str
    who: str
    why: str
    params: dict[str, float]
    frames: tuple[int, int] | None = None  # [start, end) frame indices; None: the whole session
    # A model the vendor's own software measured at these parameters (DJI's SDK: a count ->
    # temperature table), for models whose curves thermcap cannot recompute itself.
    model: dict[str, Any] | None = None

    def covers(self, frame: int) -> bool:
        return self.frames is None or self.frames[0] <= frame < self.frames[1]

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def models_named(recorded: dict[str, Any], versions: list[ModelVersion], version: int | None = None
                 ) -> dict[str, str]:
    """What every temperature product says of the model it used, as string attributes (CF, Zarr,
    HDF5 take them alike): the model recorded (version 0), every later version with the frames
    it covers, and which one the temperatures use (``version``; None: the latest covering each
    frame). A new version changes these attributes, so a product that names them cannot keep
    giving the old numbers under the same description."""
    known = [0, *(v.version for v in versions)]
    if version is None:
        used = "the latest version covering each frame" + (f" (versions {', '.join(map(str, known))}; 0 is the "
                                                             f"model recorded)" if versions else " (0, the model "
                                                                                              "recorded)")
    else:
        used = str(version)
    return {"radiometric_model": json.dumps(recorded, sort_keys=True),
            "radiometric_model_versions": json.dumps([v.to_dict() for v in versions], sort_keys=True),
            "model_version": used}


#: parsed radiometry.json by path, with the identity of the file they were parsed from
_PARSED: dict[Path, tuple[tuple[int, int, int, int], list[ModelVersion]]] = {}
_PARSED_MAX = 256


def read_versions(session_dir: str | os.PathLike) -> list[ModelVersion]:
    """The session's model versions, oldest first. A server asks for every Zarr key and frame,
    so the file is parsed again only when it is another file (``add_version`` replaces it
    whole: a new inode, size or time), and a stat is all an unchanged one costs."""
    path = Path(session_dir) / RADIOMETRY_JSON
    try:
        st = path.stat()
    except FileNotFoundError:
        return []
    ident = (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    hit = _PARSED.get(path)
    if hit is not None and hit[0] == ident:
        return list(hit[1])
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        return []
    except ValueError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    versions = versions_from(doc)
    if len(_PARSED) >= _PARSED_MAX:
        _PARSED.pop(next(iter(_PARSED)))
    _PARSED[path] = (ident, versions)
    return list(versions)


def versions_from(doc: dict[str, Any]) -> list[ModelVersion]:
    """The versions a ``radiometry.json`` document holds (read from a folder, or a bucket)."""
    return [ModelVersion(v["version"], v["at"], v["who"], v["why"], dict(v["params"]),
                         tuple(v["frames"]) if v.get("frames") else None, v.get("model"))
            for v in doc.get("versions", [])]


def add_version(session_dir: str | os.PathLike, base: RadiometricModel, params: dict[str, float], *, who: str,
                why: str, frames: tuple[int, int] | None = None,
                measured: RadiometricModel | None = None) -> ModelVersion:
    """Record a re-parameterisation (checked against the model first); append-only.
    ``measured``: the model a vendor's software gave at ``params`` (then ``base`` is not
    re-parameterised by thermcap)."""
    if not why.strip():
        raise ValueError("say why the parameters change (it is kept with the version)")
    if measured is None:
        reparameterise(base, params)
    versions = read_versions(session_dir)
    v = ModelVersion(len(versions) + 1, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), who, why,
                     {k: float(x) for k, x in params.items()}, frames,
                     measured.to_dict() if measured is not None else None)
    path = Path(session_dir) / RADIOMETRY_JSON
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"versions": [x.to_dict() for x in [*versions, v]]}, indent=1))
    os.replace(tmp, path)
    return v


_MEASURED: dict[int, tuple[ModelVersion, RadiometricModel]] = {}


def _measured(version: ModelVersion) -> RadiometricModel:
    """A measured version's model, built once per version read (a DJI table has thousands of
    entries, and temperatures are asked for frame by frame). Keyed by the object, which the
    entry keeps alive, so a key is never reused by another session's version."""
    from thermcap.recorder.radiometry.base import model_from_dict

    got = _MEASURED.get(id(version))
    if got is None or got[0] is not version:
        if len(_MEASURED) > 32:
            _MEASURED.clear()
        got = (version, model_from_dict(dict(version.model or {})))
        _MEASURED[id(version)] = got
    return got[1]


def model_for_frame(base: RadiometricModel, versions: list[ModelVersion], frame: int,
                    overrides: dict[str, float] | None = None) -> tuple[RadiometricModel, int]:
    """The model a frame's temperatures use, and its version (the latest covering the frame);
    per-request ``overrides`` go on top (version reported as the base it started from)."""
    chosen = next((v for v in reversed(versions) if v.covers(frame)), None)
    if chosen is not None and chosen.model is not None:
        model = _measured(chosen)
    else:
        model = reparameterise(base, chosen.params) if chosen else base
    if overrides:
        model = reparameterise(model, overrides)
    return model, chosen.version if chosen else 0
