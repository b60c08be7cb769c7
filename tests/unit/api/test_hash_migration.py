"""Migration 0008 turns an older index's hex frame hashes into 32 bytes each, keeps every
value, reads back the same hex, and goes back on downgrade: on SQLite here, on PostgreSQL in
the system tier (``test_binary_hashes_on_postgresql``)."""

from __future__ import annotations

import hashlib

from alembic import command
from alembic.config import Config
from sqlalchemy import select, text

from thermcap.api import db

H = [hashlib.sha256(bytes([i])).hexdigest() for i in range(4)]


def _alembic(conn):
    cfg = Config()
    cfg.set_main_option("script_location", str(db.__file__).replace("db.py", "migrations"))
    cfg.attributes["connection"] = conn
    return cfg


def check_binary_hashes(engine) -> None:
    with engine.begin() as conn:
        command.upgrade(_alembic(conn), "0007")
        if conn.dialect.name == "postgresql":  # as an index made before 0008 has them
            for col in ("sha256", "sidecar_sha256"):
                conn.execute(text(f"ALTER TABLE frames ALTER COLUMN {col} TYPE varchar(64) USING NULL"))
        conn.execute(text("INSERT INTO sessions (id, path, frames, frames_dropped, has_targets, has_slew_to_cue, "
                          "source_deleted, fingerprint, indexed_at) VALUES ('m', 'm', 2, 0, false, false, false, "
                          "'', 0)"))
        conn.execute(text("INSERT INTO frames (session_id, idx, timestamp_ns, slew_to_cue, target_count, sha256, "
                          "sidecar_sha256) VALUES ('m', 0, 1, false, 0, :a, :b), ('m', 1, 2, false, 0, :c, NULL)"),
                     {"a": H[0], "b": H[1], "c": H[2]})
    db.migrate(engine)
    with engine.connect() as conn:
        rows = conn.execute(select(db.frames.c.idx, db.frames.c.sha256, db.frames.c.sidecar_sha256)
                            .order_by(db.frames.c.idx)).all()
        assert [tuple(r) for r in rows] == [(0, H[0], H[1]), (1, H[2], None)]
        stored = conn.execute(text("SELECT sha256 FROM frames WHERE idx = 0")).scalar()
        assert bytes(stored) == bytes.fromhex(H[0])  # 32 bytes, not 64 characters
    with engine.begin() as conn:
        conn.execute(db.frames.insert().values(session_id="m", idx=2, timestamp_ns=3, slew_to_cue=False,
                                               target_count=0, sha256=H[3]))
        command.downgrade(_alembic(conn), "0007")
        assert conn.execute(text("SELECT sha256 FROM frames ORDER BY idx")).scalars().all() == [H[0], H[2], H[3]]
    db.migrate(engine)


def test_binary_hashes_on_sqlite(tmp_path):
    engine = db.make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    check_binary_hashes(engine)
