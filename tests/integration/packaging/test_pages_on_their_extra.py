"""A how-to page runs top to bottom in a fresh virtual environment that holds only what the
page's first block installs: a page that needs an extra it never names (the maps page stopped
at its first command on a fresh machine) fails here. Real installs from this checkout, with
pip's cache as the run has it (the registry is reached only for what the cache lacks)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.docs.test_docs_blocks import ROOT, blocks, run_page

pytestmark = pytest.mark.system


@pytest.mark.parametrize("page", ["docs/how-to/maps.md", "docs/how-to/fleet.md"])
def test_a_page_runs_on_what_its_first_block_installs(page, tmp_path, monkeypatch):
    path = ROOT / page
    first = blocks(path)[0]
    installs = [line.strip() for line in first.body.splitlines() if line.strip().startswith("pip install")]
    assert installs and all(re.match(r"pip install -e '\.\[[a-z,]+\]'$", line) for line in installs), \
        f"{page}: its first block installs its extra from the checkout ({installs})"
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    env = {**os.environ, "PATH": f"{venv / 'bin'}{os.pathsep}{os.environ['PATH']}", "VIRTUAL_ENV": str(venv),
           "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    env.pop("PYTHONPATH", None)
    for line in installs:
        done = subprocess.run(["bash", "-c", line], cwd=ROOT, env=env, capture_output=True, text=True, timeout=1200)
        assert done.returncode == 0, f"{line}:\n{done.stderr[-3000:]}"
    thermcap = Path(venv / "bin" / "thermcap")
    assert thermcap.is_file()
    work = tmp_path / "page"
    work.mkdir()
    run_page(path, work, monkeypatch, environ=env)
