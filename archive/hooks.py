"""Who is told when a session's archive verified.

The archive cannot import the API, whose index wants to know; the ``thermcap`` facade registers
the API's hook here when it is imported. Import-light: that happens on every ``import thermcap``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

__all__ = ["ON_ARCHIVED", "OnArchived", "register_on_archived"]

# hook(session_dir, root): the archive of session_dir verified and its manifest is written
OnArchived = Callable[[Path, Path], None]
ON_ARCHIVED: list[tuple[str, OnArchived]] = []


def register_on_archived(name: str, hook: OnArchived) -> None:
    if all(n != name for n, _ in ON_ARCHIVED):
        ON_ARCHIVED.append((name, hook))
