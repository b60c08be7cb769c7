"""Every frame codec round-trips bit-exact, has a JSON config, and is registered."""

from __future__ import annotations

import pytest

from thermcap.archive.codecs import codec_registry, get_codec
from thermcap.recorder.capture.sources.sim import SimSource

CODECS = [get_codec(cid) for cid in sorted(codec_registry)]


def test_hdf5_archives_open_in_hdf5_1_10_tools(tmp_path):
    """h5py's wheel carries HDF5 2.x; a file written with libver="latest" fails `h5dump -H` of
    Debian's hdf5-tools 1.10 with "internal error". .ci/run installs hdf5-tools."""
    import shutil
    import subprocess

    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.capture.recorder import Recorder

    h5dump = shutil.which("h5dump")
    if h5dump is None:
        pytest.skip("h5dump is not installed (apt-get install hdf5-tools; .ci/run does this)")
    Recorder(SimSource(width=64, height=48, frames=10, paced=False), tmp_path, session_id="s", analysis=False).run()
    archive_session(tmp_path / "sessions" / "s", ["hdf5"])
    r = subprocess.run([h5dump, "-H", str(tmp_path / "sessions" / "s" / "archive" / "hdf5" / "s.h5")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert 'DATASET "frames"' in r.stdout
    assert "H5T_STD_U16LE" in r.stdout


