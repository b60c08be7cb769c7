"""``thermcap sync`` from a "vehicle" to SeaweedFS through a link that throttles and cuts the
connection every few MB, then ``thermcap sync-confirm`` on the cloud side: every cut costs at most
one part sent again, the cap holds, no byte is lost, and every receipt verifies."""

from __future__ import annotations

import json
import time

import pytest

from tests.support.link import FlakyLink
from thermcap.archive.blobs import open_store
from thermcap.archive.receipts import confirm_synced
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy
from thermcap.recorder.sync.engine import Syncer
from thermcap.recorder.sync.rate import parse_rate
from thermcap.recorder.sync.targets import S3Target

pytest.importorskip("boto3", reason="boto3 is in the sync extra (pip install 'thermcap[sync]')")
MiB = 1 << 20


def test_sync_through_a_link_that_cuts_and_throttles(seaweedfs, tmp_path, monkeypatch):
    for k in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY"):
        monkeypatch.setenv(k, seaweedfs[k])
    root = tmp_path / "vehicle"
    rec = Recorder(SimSource(width=640, height=512, frames=120, paced=False, seed=9), root, session_id="lte",
                   analysis=False, recover_leftovers=False,
                   policy=SegmentPolicy(max_duration_s=None, max_bytes=16 * MiB))
    assert rec.run().ok
    segs = sorted((root / "sessions" / "lte").glob("*.mcap"))
    total = sum(s.stat().st_size for s in segs)
    host, port = seaweedfs["endpoint"].removeprefix("http://").split(":")
    cap = 4_000_000
    link = FlakyLink((host, int(port)), rate=6_000_000, cut_every=7 * MiB)
    prefix = f"link-{tmp_path.name}"
    try:
        syncer = Syncer(root, S3Target(seaweedfs["bucket"], endpoint=link.endpoint, prefix=prefix, timeout_s=10),
                        rate=parse_rate("4MB/s"), part_size=5 * MiB, backoff_s=0.05)
        t = time.monotonic()
        report = syncer.run_once()
        elapsed = time.monotonic() - t
    finally:
        link.close()
    assert not report.failed, report.failed
    assert link.cuts >= 3, "the link never cut: the test proves nothing"
    assert report.parts_resent <= link.cuts  # each cut costs at most the part in flight
    wire_rate = link.sent / elapsed
    assert wire_rate <= cap * 1.1, f"{wire_rate:,.0f} B/s through a {cap:,} B/s cap"
    assert wire_rate >= cap * 0.8, f"only {wire_rate:,.0f} B/s of a {cap:,} B/s cap"
    print(f"\nsync: {total:,} B in {elapsed:.1f} s, {wire_rate / cap:.2f} of the cap on the wire, "
          f"{link.cuts} cuts, {report.parts_resent} parts sent again")

    store = open_store(tmp_path, bucket=seaweedfs["bucket"], endpoint=seaweedfs["endpoint"], prefix=prefix)
    res = confirm_synced(store)
    assert sorted(res.receipted) == sorted(s.relative_to(root).as_posix() for s in segs) and not res.damaged
    for s in segs:  # zero bytes lost
        key = s.relative_to(root).as_posix()
        assert b"".join(store.iter_bytes(key)) == s.read_bytes()
    syncer.target = S3Target(seaweedfs["bucket"], endpoint=seaweedfs["endpoint"], prefix=prefix)
    assert syncer.check_receipts() == len(segs)
    st = syncer.status()
    assert sorted(st.confirmed) == sorted(s.relative_to(root).as_posix() for s in segs)
    receipt = json.loads(b"".join(store.iter_bytes(f"receipts/{segs[0].relative_to(root).as_posix()}.json")))
    assert receipt["ok"] and receipt["frames"] > 0
