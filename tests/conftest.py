"""Shared fixtures: sample folders, and a helper to run the real ``thermcap`` command."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SAMPLES = Path(__file__).resolve().parents[1].parent / "shared" / "samples"


@pytest.fixture
def samples() -> Path:
    if not SAMPLES.is_dir():
        pytest.skip(f"real sample files not present at {SAMPLES} (the shared/ folder beside the checkout)")
    return SAMPLES


def run_cli(*args: str, input: bytes | None = None, timeout: float = 120, env: dict | None = None,
            **kw) -> subprocess.CompletedProcess:
    """Run ``thermcap`` as a user would: a real process, real files."""
    full_env = {**os.environ, **(env or {})}
    r = subprocess.run([sys.executable, "-m", "recorder", *args], input=input, capture_output=True,
                       timeout=timeout, env=full_env, **kw)
    r.stdout, r.stderr = r.stdout.decode(errors="replace"), r.stderr.decode(errors="replace")
    return r
