"""Two indexers of one session at once: what `serve --workers 2` does at start-up (each worker
process indexes the root; compose's API service runs two), and a worker indexing beside it.

Both read the session's row, find it stale and write the frames file of the same new state
(the same key). One commits. The other's transaction then fails on PostgreSQL (the row the first
committed collides with its insert), and its clean-up deleted the frames file it had written:
the very file the committed row names. Every frame request then answered 503 "frame table missing
from the store" until a forced re-index. The deployment test found it, in about one run of five:
its two API workers both indexed the new session, old row None, within 10 ms of each other. Here
the other indexer's commit and the collision are placed exactly, so the test does not depend on
the race."""

from __future__ import annotations

import pytest
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from thermcap.api import db, indexing
from thermcap.api.db import make_engine, migrate
from thermcap.api.indexing import index_session
from thermcap.api.reading import frame_columns
from thermcap.archive.archiver import archive_session
from thermcap.archive.blobs import open_store
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource


@pytest.fixture()
def indexed(tmp_path):
    Recorder(SimSource(width=64, height=48, frames=30, paced=False, seed=3), tmp_path, session_id="s").run()
    archive_session(tmp_path / "sessions" / "s", ["png16"])
    engine = make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    migrate(engine)
    store = open_store(tmp_path)
    assert index_session(engine, tmp_path / "sessions" / "s", store=store)
    return engine, store, tmp_path / "sessions" / "s"


def _row(engine) -> tuple[str, str]:
    with engine.connect() as conn:
        return tuple(conn.execute(select(db.sessions.c.fingerprint, db.sessions.c.frames_key)
                                  .where(db.sessions.c.id == "s")).one())


def _make_stale(engine, store) -> None:
    """The row as an earlier state left it (the session changed since)."""
    earlier = frame_columns.frames_key("s", "earlier")
    store.put_bytes(earlier, b"the frames file of an earlier state")
    with engine.begin() as conn:
        conn.execute(db.sessions.update().where(db.sessions.c.id == "s").values(fingerprint="earlier",
                                                                                 frames_key=earlier))


def _never_indexed(engine, store) -> None:
    """No row yet: a new session, which every API worker indexes at start-up."""
    with engine.begin() as conn:
        indexing._delete_session_rows(conn, "s")


def _another_indexer_commits_first(monkeypatch, engine, store, session) -> None:
    """Once this indexer has read the row, another indexes the same state and commits; this one's
    write then collides with that row, as PostgreSQL's unique key makes it (SQLite would wait)."""
    build, delete_rows = frame_columns.FrameColumns.from_rows, indexing._delete_session_rows
    other = {"started": False, "committed": False}

    def then_the_other_commits(*args, **kwargs):
        if not other["started"]:
            other["started"] = True
            assert index_session(engine, session, store=store)  # the other indexer, to its commit
            other["committed"] = True
        return build(*args, **kwargs)

    def collides(conn, sid):
        if not other["committed"]:  # the other indexer's own write
            return delete_rows(conn, sid)
        raise IntegrityError("INSERT INTO sessions", {}, Exception("duplicate key value violates unique constraint"))

    monkeypatch.setattr(frame_columns.FrameColumns, "from_rows", staticmethod(then_the_other_commits))
    monkeypatch.setattr(indexing, "_delete_session_rows", collides)


@pytest.mark.parametrize("before", [_never_indexed, _make_stale], ids=["a new session", "a changed session"])
def test_the_frames_file_a_committed_row_names_is_never_deleted(indexed, monkeypatch, before):
    engine, store, session = indexed
    state = _row(engine)
    before(engine, store)
    _another_indexer_commits_first(monkeypatch, engine, store, session)
    assert index_session(engine, session, store=store) is False  # indexed as it is, by the other
    assert _row(engine) == state
    assert store.head(state[1]) is not None, f"the row names {state[1]}, which is gone from the store"


def test_a_failure_of_its_own_still_removes_the_file_nobody_names(indexed, monkeypatch):
    engine, store, session = indexed
    state = _row(engine)
    _never_indexed(engine, store)  # and this time nobody commits the new state: the file is this indexer's alone

    def fails(conn, sid):
        raise RuntimeError("the database went away")

    store.delete(state[1])
    monkeypatch.setattr(indexing, "_delete_session_rows", fails)
    with pytest.raises(RuntimeError, match="went away"):
        index_session(engine, session, store=store)
    assert store.head(state[1]) is None  # no orphan left behind
