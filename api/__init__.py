"""thermcap API: a FastAPI service that indexes archived sessions and serves them.

The public face is ``create_app`` and ``Settings``; they load on first use, so the ``thermcap``
command (which lists this package's subcommands) does not import FastAPI to print its help.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Settings", "create_app"]


def __getattr__(name: str) -> Any:
    if name == "create_app":
        from thermcap.api.app import create_app

        return create_app
    if name == "Settings":
        from thermcap.api.settings import Settings

        return Settings
    raise AttributeError(f"module 'api' has no attribute {name!r}")
