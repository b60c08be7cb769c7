"""``info``, ``ls`` and the API give one session one start, span, state and set of gaps (issue 64).
Before, ``info`` said nothing of gaps and took its span from every topic's messages, while the
API took the frames' times."""

from __future__ import annotations

import json
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import ApiServer, run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

pytestmark = pytest.mark.integration

T0 = 1_700_000_000_000_000_000


class _WithAHole(SimSource):
    """The simulator with frames 40..99 never delivered: a camera that went quiet for a second."""

    def frames(self) -> Iterator:
        for i, frame in enumerate(super().frames()):
            if not 40 <= i < 100:
                yield frame


def test_info_ls_and_the_api_agree(tmp_path):
    root = tmp_path / "root"
    Recorder(_WithAHole(width=64, height=48, frames=160, paced=False, seed=4, start_time_ns=T0), root,
             session_id="hole", policy=SegmentPolicy(max_duration_s=0.5), analysis=False).run()
    info = json.loads(run_cli("info", str(root / "sessions" / "hole"), "--json").stdout)
    listed = {s["id"]: s for s in json.loads(run_cli("ls", "--root", str(root), "--json").stdout)["sessions"]}["hole"]
    server = ApiServer(root)
    try:
        api = httpx.get(f"{server.url}/api/v1/sessions/hole", timeout=60).json()
    finally:
        server.stop()
    assert info["frames"] == listed["frames"] == api["frames"] == 100
    assert len(info["gaps"]) == len(api["gaps"]) == 1
    assert info["gaps"][0]["seconds"] == pytest.approx(api["gaps"][0]["seconds"], abs=1e-6)
    assert info["gaps"][0]["start"] == api["gaps"][0]["start"]
    assert info["start"] == listed["start"] == api["start"] and info["end"] == api["end"]
    assert info["duration_s"] == pytest.approx(api["duration_s"], abs=1e-6)
    assert info["duration_s"] == pytest.approx(listed["duration_s"], abs=1e-6)
    assert info["status"] == listed["state"] == api["status"]
