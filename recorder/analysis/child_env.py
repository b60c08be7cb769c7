"""The environment of a Python process the recorder starts (the detector's, the kernels'
compiler): the parent's, with its import path, so the child imports the same thermcap (a
checkout on ``sys.path``, not only an installed copy)."""

from __future__ import annotations

import os
import sys

__all__ = ["child_env"]


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    paths = [p for p in sys.path if p]
    env["PYTHONPATH"] = os.pathsep.join(paths + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env
