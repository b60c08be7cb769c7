"""Synced sessions land in the cloud's root only whole and receipted: a session still recording,
a segment with no receipt, or bytes that differ from their receipt wait (and say why); a landed
session is the vehicle's, file for file, and its landing never leaves a half folder."""

from __future__ import annotations

import json
import shutil

from thermcap.archive.blobs import open_store
from thermcap.archive.landing import land_synced
from thermcap.archive.receipts import confirm_synced
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy


def _depot(tmp_path):
    vehicle = tmp_path / "vehicle"
    for sid in ("a", "b"):
        Recorder(SimSource(width=64, height=48, frames=40, paced=False, seed=3), vehicle, session_id=sid,
                 policy=SegmentPolicy(max_duration_s=0.3), analysis=False).run()
    depot = tmp_path / "depot"
    shutil.copytree(vehicle / "sessions", depot / "sessions")  # what `thermcap sync --to` leaves
    return vehicle, depot


def test_only_whole_receipted_sessions_land(tmp_path):
    vehicle, depot = _depot(tmp_path)
    store = open_store(depot)
    cloud = tmp_path / "cloud"
    meta = json.loads((depot / "sessions/b/session.json").read_text())
    (depot / "sessions/b/session.json").write_text(json.dumps({**meta, "status": "recording"}))
    first = land_synced(store, cloud)
    assert first.landed == [] and "no receipt" in first.waiting["a"] and "recording" in first.waiting["b"]
    confirm_synced(store)
    (depot / "sessions/b/session.json").write_text(json.dumps(meta))
    seg = sorted((depot / "sessions/b").glob("*.mcap"))[1]
    data = bytearray(seg.read_bytes())
    data[-100] ^= 1  # the bucket's copy rots after its receipt (same size)
    seg.write_bytes(bytes(data))
    second = land_synced(store, cloud)
    assert second.landed == ["a"] and "differ from the receipt" in second.damaged["b"]
    assert (cloud / "sessions/a").is_dir() and not (cloud / "sessions/b").exists()
    assert not list((cloud / "sessions").glob("*.partial"))
    for p in (vehicle / "sessions/a").iterdir():
        assert (cloud / "sessions/a" / p.name).read_bytes() == p.read_bytes()
    again = land_synced(store, cloud)
    assert again.already == 1


def test_a_second_landing_on_the_same_root_waits_its_turn(tmp_path):
    """Two `sync-confirm --into` runs on one root used to download the same session into the
    same ``.partial`` folder, the second deleting the first's half-written files under it, so
    the first could rename the second's half folder into place. One lands at a time; the other
    is refused, naming who holds the root, and touches nothing."""
    import pytest

    from thermcap.recorder.exceptions import SessionBusyError
    from thermcap.recorder.storage.lock import lock_session

    _vehicle, depot = _depot(tmp_path)
    store = open_store(depot)
    confirm_synced(store)
    cloud = tmp_path / "cloud"
    (cloud / "sessions").mkdir(parents=True)
    held = lock_session(cloud, "landing")  # another run, landing here now
    assert held is not None
    try:
        with pytest.raises(SessionBusyError, match="landing"):
            land_synced(store, cloud)
        assert list((cloud / "sessions").iterdir()) == []
    finally:
        held.release()
    assert sorted(land_synced(store, cloud).landed) == ["a", "b"]
