"""sync beside a ring: a segment the ring evicts between sync listing the folder and looking at
the file is not an error. The hour-long vehicle soak ended when ``sync --watch`` died this way
(``error: [Errno 2] No such file or directory: .../0062.mcap``) 15 minutes in: the listing is
the ring's to change at any moment, so no pass, status or report may trust it."""

from __future__ import annotations

from pathlib import Path

from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.sync.engine import Syncer
from thermcap.recorder.sync.plan import plan_root
from thermcap.recorder.sync.targets import DirTarget


def _root_with_segments(tmp_path: Path, n: int) -> Path:
    root = tmp_path / "vehicle"
    session = root / "sessions" / "drive"
    session.mkdir(parents=True)
    (session / "session.json").write_text('{"session_id": "drive", "ring": true}')
    for i in range(n):
        (session / f"{i:04d}.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(100) * (i + 1))
    return root


def _evicted_after_listing(monkeypatch, gone: set[str]) -> None:
    """The ring deletes these right after sync listed the folder: listed, then not there."""
    listed = SessionLayout.segments

    def segments(self: SessionLayout) -> list[Path]:
        out = listed(self)
        for p in out:
            if p.name in gone:
                p.unlink(missing_ok=True)
        return out

    monkeypatch.setattr(SessionLayout, "segments", segments)


def test_a_segment_evicted_after_listing_is_left_out_of_the_plan(tmp_path, monkeypatch):
    root = _root_with_segments(tmp_path, 4)
    _evicted_after_listing(monkeypatch, {"0001.mcap"})
    keys = [i.key for i in plan_root(root)]
    assert "sessions/drive/0001.mcap" not in keys
    assert {"sessions/drive/0000.mcap", "sessions/drive/0002.mcap", "sessions/drive/0003.mcap"} <= set(keys)


def test_status_and_a_pass_live_through_an_eviction(tmp_path, monkeypatch):
    root = _root_with_segments(tmp_path, 4)
    syncer = Syncer(root, DirTarget(tmp_path / "depot"))
    _evicted_after_listing(monkeypatch, {"0002.mcap"})
    report = syncer.run_once()
    assert not report.failed
    st = syncer.status()
    assert "sessions/drive/0002.mcap" not in st.pending + st.uploaded
    assert (tmp_path / "depot" / "sessions" / "drive" / "0003.mcap").is_file()


def test_freeing_lives_through_a_segment_the_ring_evicts_meanwhile(tmp_path, monkeypatch):
    import thermcap.recorder.sync.engine as engine
    from thermcap.recorder.storage.sync_journal import ObjectState

    root = _root_with_segments(tmp_path, 2)
    syncer = Syncer(root, DirTarget(tmp_path / "depot"))
    for i in range(2):
        p = root / "sessions" / "drive" / f"{i:04d}.mcap"
        syncer.journal.put(ObjectState(f"sessions/drive/{p.name}", p.stat().st_size, "0" * 64, p.stat().st_mtime_ns,
                                       state="confirmed"))
    real = engine.file_sha256

    def evicted_while_hashed(path: Path) -> str:
        path.unlink()  # the ring took it between the look and the hash
        return real(path)

    monkeypatch.setattr(engine, "file_sha256", evicted_while_hashed)
    assert syncer.delete_confirmed() == []  # nothing freed on sync's word, and no error
