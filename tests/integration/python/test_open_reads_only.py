"""``thermcap.open(folder)`` reads a data root where it lies: on a copy whose every byte, name
and time is compared before and after, in a Python that cannot import the server's packages
(FastAPI, SQLAlchemy, uvicorn, Alembic), the counts come out bit-exact and nothing is written."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tests.support.api_data import make_root
from thermcap.archive.archiver import archive_session
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

SERVER_PACKAGES = ("fastapi", "sqlalchemy", "uvicorn", "alembic", "starlette")

# A finder that refuses the server's packages, as on a machine installed without the `server` extra.
_BLOCK = textwrap.dedent(f"""
    import sys
    class _NoServer:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in {SERVER_PACKAGES!r}:
                raise ModuleNotFoundError(f"No module named {{name!r}} (blocked: no server extra)")
            return None
    sys.meta_path.insert(0, _NoServer())
""")


def _snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root``: kind, size, mtime and, for files, the bytes' sha256."""
    out: dict[str, tuple] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath, name)
            st = p.lstat()
            digest = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else ""
            out[str(p.relative_to(root))] = (p.is_dir(), st.st_size if p.is_file() else 0, st.st_mtime_ns, digest)
    return out


@pytest.fixture(scope="module")
def shared_root(tmp_path_factory) -> Path:
    root = make_root(tmp_path_factory.mktemp("readonly"))
    src = tmp_path_factory.mktemp("src")
    make_root(src)  # a second copy of s-archived, archived again with its source deleted
    shutil.copytree(src / "sessions" / "s-crossover", root / "sessions" / "s-deleted")
    meta = root / "sessions" / "s-deleted" / "session.json"
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "session_id": "s-deleted"}))
    shutil.rmtree(root / "sessions" / "s-deleted" / "archive")
    archive_session(root / "sessions" / "s-deleted", ["hdf5", "tiff-lzw"], delete_source=True)
    for p in sorted(root.rglob("*"), reverse=True):  # what a read-only share looks like
        p.chmod(0o555 if p.is_dir() else 0o444)
    return root


def test_open_writes_nothing_and_needs_no_server_packages(shared_root, tmp_path):
    expected = {sid: np.stack([f.pixels for f in iter_session_frames(shared_root / "sessions" / sid)])
                for sid in ("s-archived", "s-mcap-only", "s-deleted")}
    out = tmp_path / "counts.npz"
    script = _BLOCK + textwrap.dedent(f"""
        import numpy as np, thermcap
        got = {{}}
        for sid in ("s-archived", "s-mcap-only", "s-deleted"):
            s = thermcap.open({str(shared_root)!r} + "/sessions/" + sid)
            ds = s.to_xarray(chunk_frames=7)
            got[sid] = ds.counts.values
            assert np.isfinite(ds.temperature.isel(time=0).values).any()
            assert s.frame(1).sidecar, sid
        for name in {SERVER_PACKAGES!r}:
            assert name not in sys.modules, name
        np.savez({str(out)!r}, **got)
    """)
    before = _snapshot(shared_root)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600,
                       env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    assert r.returncode == 0, r.stderr
    assert _snapshot(shared_root) == before  # not a byte, a name or a time changed
    got = np.load(out)
    for sid, counts in expected.items():
        assert got[sid].dtype == np.uint16 and np.array_equal(got[sid], counts), sid


def test_a_damaged_copy_is_passed_over_for_an_intact_one(shared_root, tmp_path):
    """The hdf5 copy (cheapest to stream, read first for this session) cut to half its size: every
    frame still comes out bit-exact from the tiff-lzw copy, and the damage is reported."""
    import thermcap

    root = tmp_path / "root"
    shutil.copytree(shared_root, root)
    for p in root.rglob("*"):
        p.chmod(0o755 if p.is_dir() else 0o644)
    expected = [f.pixels for f in iter_session_frames(shared_root / "sessions" / "s-deleted")]
    (h5,) = (root / "sessions" / "s-deleted" / "archive" / "hdf5").glob("*.h5")
    h5.write_bytes(h5.read_bytes()[: h5.stat().st_size // 2])
    s = thermcap.open(root / "sessions" / "s-deleted")
    for i in (0, len(expected) // 2, len(expected) - 1):
        assert np.array_equal(s.counts(i), expected[i])
    assert s.frames.damage.total >= 1 and s.frames.damage.recent[-1].copy.startswith("hdf5:")
