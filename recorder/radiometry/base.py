"""The model contract (``RadiometricModel``), the registry of kinds, and rebuilding a model from a
session's JSON."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np

from thermcap.recorder.registry import Registry

T = TypeVar("T", bound=type)
__all__ = ["RadiometricModel", "TemperatureUnavailable", "describe_model", "model_from_dict", "register_model"]


@runtime_checkable
class RadiometricModel(Protocol):
    kind: ClassVar[str]

    def to_celsius(self, raw: np.ndarray) -> np.ndarray: ...

    def to_dict(self) -> dict[str, Any]: ...



_MODELS: Registry[Any] = Registry("radiometric model kind", lambda kind, known: ValueError(
    f"unknown radiometric model kind {kind!r}; known: {known}"))



def register_model(cls: T) -> T:
    """Class decorator: make a model kind rebuildable from session metadata."""
    _MODELS.register(cls.kind, cls)  # type: ignore[attr-defined]
    return cls


def model_from_dict(data: dict[str, Any]) -> RadiometricModel:
    """Rebuild a model from ``to_dict()`` output; unknown kinds and fields are errors, not guesses."""
    if not isinstance(data, dict) or "kind" not in data:
        raise ValueError(f"radiometric model must be an object with a 'kind', got {data!r}")
    kind = data["kind"]
    cls: Any = _MODELS.factory(kind)
    params = {k: v for k, v in data.items() if k not in ("kind", "temperature")}
    known = {f.name for f in fields(cls)}
    unknown = set(params) - known
    if unknown:
        raise ValueError(f"radiometric model {kind!r} has unknown parameters {sorted(unknown)}")
    return cls(**params)


def describe_model(model: RadiometricModel) -> dict[str, Any]:
    """A model as a sidecar, a listing or a per-file report shows it: whole, except a lookup table,
    which shows its identity (source, entries, sha256) instead of thousands of entries."""
    summary = getattr(model, "summary", None)
    return summary() if summary is not None else model.to_dict()


class TemperatureUnavailable(ValueError):
    """The counts are kept bit-exact, but no honest temperature can be computed here."""

