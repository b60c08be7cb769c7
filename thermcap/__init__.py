"""thermcap: record, archive and serve radiometric thermal camera sessions (Gray16 on MCAP).

The public Python API is what this module exports (``__all__``)::

    import thermcap

    session = thermcap.open("thermcap-data/sessions/flight-07")   # a folder, an id, s3:// or http(s)://
    ds = session.to_xarray()                                        # lazy: counts (uint16), temperature (°C)
    ds.temperature.isel(time=0).plot()

The three rooms below it (``thermcap.recorder``, ``thermcap.archive``, ``thermcap.api``) are the
implementation: importable, but free to change between releases. This package sits above them
and is the only place that wires them together (``_wiring``). Names load on first use, so
``import thermcap`` and the ``thermcap`` command start quickly.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

from thermcap import _wiring

_wiring.connect()

if TYPE_CHECKING:
    from thermcap.client import Client, ServerError
    from thermcap.opening import open
    from thermcap.session import Frame, ModelVersion, Session

__all__ = ["Client", "Frame", "ModelVersion", "ServerError", "Session", "__version__", "open"]

_WHERE = {"open": "thermcap.opening", "Session": "thermcap.session", "Frame": "thermcap.session",
          "ModelVersion": "thermcap.session", "Client": "thermcap.client", "ServerError": "thermcap.client"}


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("thermcap")
        except PackageNotFoundError:  # a source tree never installed
            return "0.0.0"
    if name in _WHERE:
        return getattr(import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'thermcap' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
