"""Radiometric models: raw counts <-> temperature, carried as data in every session.

A model is a small frozen dataclass with a ``kind`` and JSON-safe parameters, so a session's
metadata fully describes how to turn its counts into temperatures years later, without the code
path that recorded it. ``model_from_dict`` rebuilds a model from that JSON; importers register
further kinds (FLIR Planck, DJI) with ``register_model``.

Each kind lives in its own module (``linear``, ``planck``, ``lookup``); importing the package
registers them all, so ``model_from_dict`` knows every kind a session may name.
"""

from thermcap.recorder.radiometry.base import (
    RadiometricModel,
    TemperatureUnavailable,
    describe_model,
    model_from_dict,
    register_model,
)
from thermcap.recorder.radiometry.linear import DEFAULT_MODEL, LinearModel, ScaledKelvinModel
from thermcap.recorder.radiometry.lookup import DjiModel, LookupTableModel
from thermcap.recorder.radiometry.planck import FlirPlanckModel, TerraRefPlanckModel

__all__ = [
    "DEFAULT_MODEL",
    "DjiModel",
    "FlirPlanckModel",
    "LinearModel",
    "LookupTableModel",
    "RadiometricModel",
    "ScaledKelvinModel",
    "TemperatureUnavailable",
    "TerraRefPlanckModel",
    "describe_model",
    "model_from_dict",
    "register_model",
]
