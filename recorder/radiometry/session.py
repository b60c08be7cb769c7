"""A session's temperatures: the one place its counts become degrees.

Every product that gives a temperature (exports, maps, mosaics, summaries, the API's measures,
the Python reader) asks here, so they cannot disagree: the model is the session's recorded one
at the version that covers the frame (``radiometry.json``: the latest, unless a version is
named), and the pixels the session's bad-pixel map lists are NaN (``bad_pixels="nan"``, the
default) or left as the sensor gave them (``"keep"``). The stored counts never change. Each
result says which model version and which rule it used, for the product to carry in its own
metadata.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from thermcap.recorder.radiometry.base import RadiometricModel, model_from_dict
from thermcap.recorder.radiometry.params import ModelVersion, model_for_frame, read_versions, reparameterise

__all__ = ["APPROXIMATE_NOTE", "BAD_PIXEL_RULES", "FrameTemperatures", "SessionTemperatures", "approximate_frames",
           "bad_pixel_mask", "read_bad_pixel_map"]

#: What happens to the pixels the bad-pixel map lists: NaN (no temperature), or kept as measured.
BAD_PIXEL_RULES = ("nan", "keep")


def read_bad_pixel_map(session_dir: str | Path, camera: str | None = None) -> np.ndarray | None:
    """The session's bad-pixel map (the ``bad_pixel_map.json`` attachment every segment, and the
    archive's extras.mcap, carry; ``CAMERA/bad_pixel_map.json`` in a session of several) as a
    boolean mask; None where it has none."""
    from thermcap.recorder.storage.reader import frame_files

    for path in frame_files(session_dir):
        try:
            with open(path, "rb") as f:
                mask = bad_pixel_mask(f, camera)
        except OSError:
            continue
        if mask is not None:
            return mask
    return None


def bad_pixel_mask(f: BinaryIO, camera: str | None = None) -> np.ndarray | None:
    """The bad-pixel map attached to one MCAP file (a segment, an extras.mcap on disk or read
    from a bucket by ranges), as a boolean mask; None where it has none or cannot be read."""
    from mcap.reader import make_reader

    want = f"{camera}/bad_pixel_map.json" if camera else "bad_pixel_map.json"
    try:
        found = {att.name: att.data for att in make_reader(f, validate_crcs=True).iter_attachments()
                 if att.name.endswith("bad_pixel_map.json")}
        data = found.get(want) or (next(iter(found.values())) if camera is None and len(found) == 1 else None)
        if data is None:
            return None
        bpm = json.loads(data)
        mask = np.zeros((int(bpm["height"]), int(bpm["width"])), bool)
        for x, y in bpm.get("pixels", []):
            mask[int(y), int(x)] = True
        return mask
    except (OSError, ValueError, KeyError, IndexError):
        return None


#: What an approximate product says of itself, where GIS tools show it (band description, metadata).
APPROXIMATE_NOTE = ("APPROXIMATE: DJI's uncorrected blackbody formula without DJI's Thermal SDK, several degrees C off "
                    "(no emissivity, reflection or atmosphere correction)")


def approximate_frames(temps: SessionTemperatures, frames: int) -> int:
    """How many of a session's frames would get approximate temperatures from ``temps``."""
    return sum(bool(getattr(temps.model_for(i)[0], "approximate", False)) for i in range(frames))


@dataclass(frozen=True)
class FrameTemperatures:
    """One frame's °C, and what made them."""

    celsius: np.ndarray  # float32 (H, W); NaN at bad pixels under the "nan" rule
    model: RadiometricModel
    model_version: int
    bad_pixels: int  # how many pixels the map lists
    rule: str

    def finite(self) -> np.ndarray:
        """The frame's temperatures without the bad pixels, flat: what a statistic is taken of."""
        flat = self.celsius.ravel()
        return flat[np.isfinite(flat)] if self.bad_pixels and self.rule == "nan" else flat

    @property
    def approximate(self) -> bool:
        """The model only approximates temperature (DJI's uncorrected blackbody, without the SDK)."""
        return bool(getattr(self.model, "approximate", False))

    def describe(self) -> dict[str, Any]:
        """What a product says of its numbers (TIFF metadata, JSON, reports)."""
        return {"model_version": self.model_version, "radiometric_model": self.model.to_dict(),
                **({"temperature_quality": APPROXIMATE_NOTE} if self.approximate else {}),
                "bad_pixels": {"listed": self.bad_pixels, "rule": self.rule,
                               "meaning": "NaN: no temperature (the session's bad-pixel map)" if self.rule == "nan"
                               else "kept as the sensor measured them"}}


@dataclass
class SessionTemperatures:
    base: RadiometricModel
    versions: list[ModelVersion] = field(default_factory=list)
    bad_pixel_map: np.ndarray | None = None
    version: int | None = None  # None: the latest version covering each frame
    bad_pixels: str = "nan"
    overrides: dict[str, float] | None = None  # object parameters of this one request
    _built: dict[int, tuple[RadiometricModel, int]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.bad_pixels not in BAD_PIXEL_RULES:
            raise ValueError(f"bad pixels: use one of {', '.join(BAD_PIXEL_RULES)}, not {self.bad_pixels!r}")
        known = [0, *(v.version for v in self.versions)]
        if self.version is not None and self.version not in known:
            raise ValueError(f"model version {self.version}: this session has versions {known}")

    @classmethod
    def of(cls, session_dir: str | Path, meta: dict[str, Any] | None = None, *, version: int | None = None,
           bad_pixels: str = "nan", overrides: dict[str, float] | None = None) -> SessionTemperatures:
        from thermcap.recorder.storage.reader import read_session_meta

        meta = read_session_meta(session_dir) if meta is None else meta
        base = model_from_dict(meta.get("radiometric_model") or {"kind": "linear"})
        return cls(base, read_versions(session_dir),
                   read_bad_pixel_map(session_dir) if bad_pixels == "nan" else None,
                   version=version, bad_pixels=bad_pixels, overrides=overrides)

    def model_for(self, frame: int) -> tuple[RadiometricModel, int]:
        """The model frame ``frame``'s temperatures use, and its version."""
        if self.version is None:
            key = next((v.version for v in reversed(self.versions) if v.covers(frame)), 0)
        else:
            key = self.version
        if key not in self._built:
            if self.version is None:
                self._built[key] = model_for_frame(self.base, self.versions, frame, self.overrides)
            else:  # one version named for every frame
                chosen = next((v for v in self.versions if v.version == key), None)
                model = self.base if chosen is None else model_from_dict(dict(chosen.model)) if chosen.model \
                    else reparameterise(self.base, chosen.params)
                self._built[key] = (reparameterise(model, self.overrides) if self.overrides else model, key)
        return self._built[key]

    def celsius(self, frame: int, counts: np.ndarray) -> FrameTemperatures:
        """Frame ``frame``'s counts in °C (raises the model's TemperatureUnavailable where it has
        none); the counts are not changed."""
        model, version = self.model_for(frame)
        temps = np.array(model.to_celsius(counts), dtype=np.float32)
        listed = 0
        mask = self.bad_pixel_map
        if mask is not None and mask.shape == temps.shape:
            listed = int(mask.sum())
            if self.bad_pixels == "nan" and listed:
                temps[mask] = np.nan
        return FrameTemperatures(temps, model, version, listed, self.bad_pixels)
