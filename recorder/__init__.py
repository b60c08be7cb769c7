"""thermcap recorder: capture radiometric Gray16 frames with ICD sidecars into MCAP segments."""

from __future__ import annotations

from typing import Any

__all__ = ["__version__"]


def __getattr__(name: str) -> Any:
    # read on first use: importlib.metadata costs tens of milliseconds at every start of the command
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("thermcap")
        except PackageNotFoundError:  # running from a source tree that was never installed
            return "0.0.0"
    raise AttributeError(f"module 'thermcap.recorder' has no attribute {name!r}")
