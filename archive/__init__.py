"""thermcap archive: lossless repacking, a bit-exact proof of every frame, the manifest, verify,
scrub and storage costs.

The public face loads on first use (the codecs pull in imagecodecs, h5py and tifffile), so the
``thermcap`` command can list this package's subcommands cheaply.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__all__ = ["DEFAULT_FORMATS", "archive_session", "get_codec", "get_format", "load_manifest", "scrub_root",
           "scrub_session", "verify_session"]

_WHERE = {"DEFAULT_FORMATS": "thermcap.archive.archiver", "archive_session": "thermcap.archive.archiver",
          "get_codec": "thermcap.archive.codecs",
          "get_format": "thermcap.archive.formats", "load_manifest": "thermcap.archive.manifest",
          "scrub_root": "thermcap.archive.scrub",
          "scrub_session": "thermcap.archive.scrub", "verify_session": "thermcap.archive.verify"}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'archive' has no attribute {name!r}")
