"""thermcap recorder: capture radiometric Gray16 frames with ICD sidecars into MCAP segments."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("thermcap")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"

__all__ = ["__version__"]
