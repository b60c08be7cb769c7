"""The installed distribution exposes one import name, ``thermcap``: built as a wheel, installed
into a clean virtual environment, nothing else is importable and the data files come along."""

from __future__ import annotations

import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out),
                    str(ROOT)], check=True, capture_output=True, text=True)
    (built,) = out.glob("thermcap-*.whl")
    return built


def test_the_wheel_holds_only_thermcap(wheel: Path):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"thermcap"}, tops
    for data in ("thermcap/py.typed", "thermcap/recorder/foxglove_layout.json", "thermcap/api/static/index.html",
                 "thermcap/api/migrations/script.py.mako", "thermcap/recorder/icd/__init__.py"):
        assert data in names, f"{data} missing from the wheel"
    entry = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "thermcap = thermcap.cli:main" in entry
    assert "recorder." not in entry and "archive." not in entry and "api." not in entry, entry


def test_a_clean_venv_imports_thermcap_and_nothing_generic(wheel: Path, tmp_path: Path):
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True, system_site_packages=False)
    py = env_dir / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True,
                   capture_output=True, text=True)
    probe = ("import importlib.util, sys, thermcap\n"
             "import thermcap.recorder.storage.archive_readers as r, thermcap.archive.hooks as h\n"
             "assert r.ARCHIVE_READERS and h.ON_ARCHIVED, 'the facade wires the rooms on import'\n"
             "assert thermcap.__file__.startswith(sys.prefix), thermcap.__file__\n"
             "gone = [n for n in ('recorder', 'archive', 'api') if importlib.util.find_spec(n) is not None]\n"
             "assert not gone, gone\n"
             "print(sorted(thermcap.__all__))\n")
    done = subprocess.run([str(py), "-I", "-c", probe], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "open" in done.stdout and "Session" in done.stdout
