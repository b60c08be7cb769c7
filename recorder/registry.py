"""One shape for every registry of thermcap: codecs, archive formats and radiometric models.

A registry maps a stable id (stored in files and manifests, never renamed) to a factory, and
builds an object from a config ``{"id": ..., **settings}`` or a bare id, as numcodecs does. The
archive's codec and format registries and the recorder's model registry are all ``Registry``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(dict[str, Callable[..., T]], Generic[T]):
    """``id -> factory``; ``build(config)`` makes the object, ``unknown`` says what an unknown id raises."""

    def __init__(self, what: str, unknown: Callable[[str, list[str]], Exception] | None = None) -> None:
        super().__init__()
        self.what = what
        self._unknown = unknown or (lambda key, known: KeyError(f"unknown {what} {key!r}; known: {', '.join(known)}"))

    def register(self, key: str, factory: Callable[..., T]) -> Callable[..., T]:
        self[key] = factory
        return factory

    def factory(self, key: str) -> Callable[..., T]:
        try:
            return self[key]
        except KeyError:
            raise self._unknown(str(key), sorted(self)) from None

    def build(self, config: dict[str, Any] | str) -> T:
        """``self[config["id"]](**rest)``; a bare string is an id with default settings."""
        config = {"id": config} if isinstance(config, str) else dict(config)
        key = config.pop("id", None)
        return self.factory(str(key))(**config)
