"""A data root with three real sessions, recorded and archived, shared by the API tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import ApiServer
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

W, H = 160, 120
T0 = 1_800_000_000_000_000_000


def make_root(root: Path) -> Path:
    pol = SegmentPolicy(max_duration_s=0.5)
    Recorder(SimSource(width=W, height=H, frames=60, paced=False, seed=1, start_time_ns=T0, first_cue_s=0.1), root,
             session_id="s-archived", policy=pol, analysis=False).run()
    archive_session(root / "sessions" / "s-archived", ["png16", "hdf5", "jxl"])
    Recorder(SimSource(width=W, height=H, frames=120, paced=False, seed=2, crossover=True, cue_period_s=0,
                       start_time_ns=T0 + 10**12), root, session_id="s-crossover", policy=pol, analysis=False).run()
    archive_session(root / "sessions" / "s-crossover", ["png16"])
    Recorder(SimSource(width=W, height=H, frames=30, paced=False, seed=3, start_time_ns=T0 + 2 * 10**12,
                       first_cue_s=0.1,
                       sensor_id="OTHERCAM"), root, session_id="s-mcap-only", policy=pol, analysis=False).run()
    return root


def token_server(root: Path, tokens_dir: Path, token: str, **env: str) -> ApiServer:
    """``thermcap serve`` on ``root`` that takes ``token`` (read scope) and nothing else."""
    tokens = tokens_dir / "tokens"
    tokens.write_text(f"{token}=read\n")
    return ApiServer(root, env={"THERMCAP_TOKENS_FILE": str(tokens), **env})


@pytest.fixture(scope="session")
def data_root(tmp_path_factory) -> Path:
    return make_root(tmp_path_factory.mktemp("apiroot"))


@pytest.fixture(scope="session")
def server(data_root):
    s = ApiServer(data_root)
    yield s
    s.stop()
