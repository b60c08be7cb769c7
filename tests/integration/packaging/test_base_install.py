"""The base install is what a vehicle needs: with every extra's modules made unimportable, the
vehicle's commands run, and a command that needs an extra names the one to install."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from thermcap.extras import EXTRA_FOR

pytestmark = pytest.mark.integration

# run thermcap as if only the base were installed: each extra's top-level module refuses to import
BLOCKER = """
import sys, importlib.abc
BLOCKED = set({blocked!r})
class Missing(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None
sys.meta_path.insert(0, Missing())
sys.argv = ["thermcap", *sys.argv[1:]]
from thermcap.cli import main
main()
"""


ROOT = Path(__file__).resolve().parents[3]


def _base(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    code = BLOCKER.format(blocked=sorted(EXTRA_FOR))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout, whatever is installed
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=cwd, timeout=300,
                          env=env)


def test_the_vehicle_runs_on_the_base_install(tmp_path):
    root = str(tmp_path / "root")
    steps = [["--help"], ["record", "--help"], ["record", "--root", root, "--session", "v", "--duration", "0.5",
                                                "--width", "64", "--height", "48"],
             ["info", f"{root}/sessions/v"], ["ls", "--root", root], ["recover", f"{root}/sessions/v"],
             ["sync", "--root", root, "--to", str(tmp_path / "depot")],
             ["export", "v", "--root", root, "--to", "celsius-tiff", "--out", str(tmp_path / "tiffs")]]
    for step in steps:
        r = _base(*step, cwd=tmp_path)
        assert r.returncode == 0, (step, r.stderr[-2000:])
    assert list((tmp_path / "tiffs").glob("*.tiff"))


@pytest.mark.parametrize("args,extra", [
    (["serve", "--root", "{root}", "--port", "0"], "server"),
    (["archive", "v", "--root", "{root}", "--formats", "hdf5"], "archive"),
])
def test_a_command_missing_its_extra_says_which(tmp_path, args, extra):
    root = tmp_path / "root"
    assert _base("record", "--root", str(root), "--session", "v", "--duration", "0.3", "--width", "32", "--height",
                 "24", cwd=tmp_path).returncode == 0
    r = _base(*[a.format(root=root) for a in args], cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    # the form that works from this checkout, not a package name no index holds
    assert f"pip install -e '{ROOT}[{extra}]'" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_the_message_names_the_command_after_root_options(tmp_path):
    config = tmp_path / "thermcap.toml"
    config.write_text("")
    r = _base("--config", str(config), "serve", "--root", str(tmp_path), "--port", "0", cwd=tmp_path)
    assert r.returncode == 1 and "`thermcap serve` needs" in r.stderr, r.stderr
