"""How to add an extra to the thermcap that is running, in the form that works for how it was
installed: a checkout installed in place (``pip install -e``), a checkout or a wheel file
installed from its path, or a package index. ``pip install 'thermcap[maps]'`` names a package
no index holds while thermcap is installed from its checkout, and fails on a fresh machine."""

from __future__ import annotations

import json
import shlex
from importlib import metadata
from pathlib import Path
from urllib.parse import unquote, urlparse

__all__ = ["install_command"]


def install_command(extra: str) -> str:
    """``pip install ...`` that adds ``extra`` (``"maps"``, ``"server,python"``) to this thermcap."""
    editable, where = _origin()
    if where is None:
        return f"pip install {shlex.quote(f'thermcap[{extra}]')}"
    return f"pip install {'-e ' if editable else ''}{shlex.quote(f'{where}[{extra}]')}"


def _origin() -> tuple[bool, str | None]:
    """(editable, the checkout's or wheel's path), or (False, None) for a copy from an index.
    Code that runs from a checkout was installed in place (or not at all: a checkout on the
    import path); otherwise PEP 610's ``direct_url.json`` says where pip took the copy from."""
    checkout = _checkout()
    if checkout is not None:
        return True, "." if checkout == Path.cwd().resolve() else str(checkout)
    try:
        direct = json.loads(metadata.distribution("thermcap").read_text("direct_url.json") or "null")
    except (metadata.PackageNotFoundError, ValueError):
        direct = None
    if not isinstance(direct, dict) or not str(direct.get("url", "")).startswith("file:"):
        return False, None
    return bool((direct.get("dir_info") or {}).get("editable")), unquote(urlparse(direct["url"]).path)


def _checkout() -> Path | None:
    here = Path(__file__).resolve().parents[1]  # the checkout: recorder/ sits beside pyproject.toml
    return here if (here / "pyproject.toml").is_file() else None
