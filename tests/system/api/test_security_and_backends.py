"""Tokens and scopes, idempotent indexing, and the scale-out path: PostgreSQL + SeaweedFS (S3)."""

from __future__ import annotations

import json
import shutil

import httpx
import imagecodecs
import numpy as np
import pytest
from sqlalchemy import func, select

from tests.conftest import ApiServer, run_cli
from thermcap.api import db
from thermcap.api.db import make_engine, migrate
from thermcap.api.indexing import index_root
from thermcap.recorder.storage.reader import iter_session_frames

READ, WRITE = "reader-token-123", "writer-token-456"


@pytest.fixture(scope="module")
def locked_server(data_root, tmp_path_factory):
    root = tmp_path_factory.mktemp("locked")
    shutil.copytree(data_root / "sessions", root / "sessions")
    s = ApiServer(root, env={"THERMCAP_TOKENS": f"{READ}=read;{WRITE}=read,write"})
    yield s
    s.stop()


def test_tokens_guard_every_route_but_health(locked_server):
    with httpx.Client(base_url=locked_server.url) as c:
        assert c.get("/healthz").status_code == 200
        assert c.get("/readyz").status_code == 200
        for path in ("/api/v1/sessions", "/api/v1/sessions/s-archived/frames/0", "/metrics", "/api/v1/audit",
                     "/api/v1/sessions/s-archived/archives/png16/0000.zip"):
            r = c.get(path)
            assert r.status_code == 401, path
            assert r.headers["www-authenticate"] == "Bearer", path
            assert c.get(path, headers={"Authorization": "Bearer wrong-token-000"}).status_code == 401
            assert c.get(path, headers={"Authorization": f"Bearer {READ}"}).status_code == 200, path
        assert c.post("/api/v1/index", headers={"Authorization": f"Bearer {READ}"}).status_code == 403
        r = c.post("/api/v1/index", headers={"Authorization": f"Bearer {WRITE}"})
        assert r.status_code == 200
        assert r.json()["unchanged"]


def test_tokens_are_never_logged_or_echoed(locked_server):
    with httpx.Client(base_url=locked_server.url) as c:
        r = c.get("/api/v1/sessions", headers={"Authorization": "Bearer wrong-token-000"})
    assert "wrong-token" not in r.text
    assert READ not in r.text


def test_serve_binds_loopback_by_default():
    from thermcap.api.cli import serve

    host = next(p for p in serve.params if p.name == "host")
    assert host.default == "127.0.0.1"


def _frames_indexed(engine, root) -> int:
    """Frames in the sessions' frames files (the index keeps no row per frame)."""
    from thermcap.api.reading.frame_columns import FrameColumnsCache
    from thermcap.archive.blobs import open_store

    with engine.connect() as conn:
        sids = conn.execute(select(db.sessions.c.id)).scalars().all()
    cache = FrameColumnsCache(engine, open_store(root))
    return sum(len(cache.get(sid)) for sid in sids)


def test_indexing_is_idempotent_and_picks_up_new_archives(data_root, tmp_path):
    root = tmp_path / "r"
    shutil.copytree(data_root / "sessions", root / "sessions")
    shutil.rmtree(root / "sessions" / "s-crossover" / "archive")
    engine = make_engine(f"sqlite:///{tmp_path / 'i.sqlite'}")
    migrate(engine)
    first = index_root(engine, root)
    assert sorted(first.indexed) == ["s-archived", "s-crossover", "s-mcap-only"]

    def snapshot():
        with engine.connect() as conn:
            counts = {t.name: conn.execute(select(func.count()).select_from(t)).scalar()
                      for t in (db.sessions, db.target_seconds, db.archives)}
        return {**counts, "frames": _frames_indexed(engine, root)}

    before = snapshot()
    again = index_root(engine, root)
    assert again.indexed == []
    assert snapshot() == before
    # archived while the service was down: the next scan sees it
    r = run_cli("archive", str(root / "sessions" / "s-crossover"), "--formats", "png16", "--root", str(root),
                env={"THERMCAP_DATABASE_URL": f"sqlite:///{tmp_path / 'other.sqlite'}"})
    assert r.returncode == 0, r.stderr
    assert index_root(engine, root).indexed == ["s-crossover"]
    assert snapshot()["archives"] == before["archives"] + 1  # one row per format, none per frame
    shutil.rmtree(root / "sessions" / "s-mcap-only")
    assert index_root(engine, root).removed == ["s-mcap-only"]


def test_archive_indexes_through_the_hook(data_root, tmp_path):
    root = tmp_path / "r"
    shutil.copytree(data_root / "sessions" / "s-mcap-only", root / "sessions" / "s-mcap-only")
    r = run_cli("archive", "s-mcap-only", "--formats", "png16", "--root", str(root))
    assert r.returncode == 0, r.stderr
    engine = make_engine(f"sqlite:///{root / 'index.sqlite'}")
    with engine.connect() as conn:
        assert conn.execute(select(func.count()).select_from(db.archives)).scalar() == 1
    assert _frames_indexed(engine, root) == 30


def test_postgresql_index_same_code_and_migrations(postgres_url, data_root):
    engine = make_engine(postgres_url)
    migrate(engine)
    migrate(engine)  # idempotent
    with engine.begin() as conn:
        for t in reversed(db.metadata.sorted_tables):
            conn.execute(t.delete())
    res = index_root(engine, data_root)
    assert sorted(res.indexed) == ["s-archived", "s-crossover", "s-mcap-only"]
    assert index_root(engine, data_root).indexed == []
    assert _frames_indexed(engine, data_root) == 60 + 120 + 30


def test_scale_out_postgresql_and_seaweedfs_through_the_same_routes(postgres_url, seaweedfs, data_root, tmp_path):
    """The archives live only in S3 (SeaweedFS) and the index in PostgreSQL; the API serves them."""
    root = tmp_path / "node"
    shutil.copytree(data_root / "sessions" / "s-archived", root / "sessions" / "s-archived")
    env = {"THERMCAP_DATABASE_URL": postgres_url, "THERMCAP_S3_BUCKET": seaweedfs["bucket"],
           "THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"], "AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
           "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    r = run_cli("upload", "s-archived", "--root", str(root), "--json", env=env)
    assert r.returncode == 0, r.stderr
    keys = next(iter(json.loads(r.stdout).values()))
    assert "sessions/s-archived/archive/png16/0000.zip" in keys
    # Indexed as an operator does, with the settings serve runs with: the frames file goes to S3.
    r = run_cli("index", "--root", str(root), "--force", "--json", env=env)
    assert r.returncode == 0, r.stderr
    expected = [f.pixels.copy() for f in iter_session_frames(root / "sessions" / "s-archived")]
    whole = (root / "sessions" / "s-archived" / "archive" / "png16" / "0001.zip").read_bytes()
    # Now the node loses its local archive copy: everything must come from S3.
    shutil.rmtree(root / "sessions" / "s-archived" / "archive" / "png16")
    shutil.rmtree(root / "sessions" / "s-archived" / "archive" / "jxl")
    server = ApiServer(root, env={**env, "THERMCAP_ROOT": str(root)})
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            raw = c.get("/api/v1/sessions/s-archived/frames/33", params={"format": "raw"})
            assert np.array_equal(np.frombuffer(raw.content, "<u2").reshape(expected[0].shape), expected[33])
            png = c.get("/api/v1/sessions/s-archived/frames/7", params={"format": "png16"})
            assert np.array_equal(imagecodecs.png_decode(png.content), expected[7])
            url = "/api/v1/sessions/s-archived/archives/png16/0001.zip"
            r = c.get(url, headers={"Range": "bytes=1000-1999"})
            assert r.status_code == 206
            assert r.content == whole[1000:2000]
            assert c.get(url).content == whole
            redirect = c.get(url, params={"redirect": True}, follow_redirects=False)
            assert redirect.status_code == 307
            assert seaweedfs["endpoint"] in redirect.headers["location"]
            assert httpx.get(redirect.headers["location"]).content == whole
    finally:
        server.stop()
    log_text = (server.proc.stderr.read() or b"").decode()
    assert seaweedfs["AWS_SECRET_ACCESS_KEY"] not in log_text
    assert "thermcap-test-secret" not in log_text


def _on_own_postgres_database(postgres_url: str, name: str, check) -> None:
    """``check(engine)`` on a database of its own, dropped afterwards."""
    from sqlalchemy import create_engine, text

    admin = create_engine(postgres_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f"DROP DATABASE IF EXISTS {name}"))
        conn.execute(text(f"CREATE DATABASE {name}"))
    engine = make_engine(postgres_url.rsplit("/", 1)[0] + f"/{name}")
    try:
        check(engine)
    finally:
        engine.dispose()  # its pooled connection would keep the database from being dropped
        with admin.connect() as conn:
            conn.execute(text(f"DROP DATABASE IF EXISTS {name}"))
        admin.dispose()


def test_legacy_frames_on_postgresql(postgres_url, tmp_path):
    """Migrations 0008 (bytea via decode/encode) and 0009, and the frames files written from an
    older index's rows, on PostgreSQL, on a database of its own."""
    from tests.unit.api.test_frames_migration import check_legacy_frames

    _on_own_postgres_database(postgres_url, "thermcap_migration_0008", lambda e: check_legacy_frames(e, tmp_path))


def test_downgrade_on_postgresql(postgres_url, tmp_path):
    """0009's downgrade (rows back, or an empty table with its indexes, partial indexes included)
    and 0008's (bytea back to hex), on PostgreSQL."""
    from tests.unit.api.test_frames_migration import check_downgrade

    _on_own_postgres_database(postgres_url, "thermcap_migration_down", lambda e: check_downgrade(e, tmp_path))
