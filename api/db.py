"""The index schema (SQLAlchemy Core) and the engine: SQLite in WAL mode by default, PostgreSQL
when ``THERMCAP_DATABASE_URL`` says so. The schema is created and upgraded by Alembic
(``api/migrations``), the same migrations on both databases."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from sqlalchemy import (
    BigInteger,
    Boolean,
    Column,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Table,
    Text,
    create_engine,
    event,
)
from sqlalchemy.engine import Engine

__all__ = [
    "archives",
    "downgrade",
    "events",
    "jobs",
    "make_engine",
    "metadata",
    "migrate",
    "segments",
    "sessions",
    "target_seconds",
]

metadata = MetaData()

sessions = Table(
    "sessions", metadata,
    Column("id", String(128), primary_key=True),
    Column("path", Text, nullable=False),
    Column("sensor", Text),
    Column("sensor_id", String(64)),
    Column("width", Integer),
    Column("height", Integer),
    Column("fps", Float),
    Column("start_ns", BigInteger),
    Column("end_ns", BigInteger),
    Column("frames", Integer, nullable=False, default=0),
    Column("frames_dropped", Integer, nullable=False, default=0),
    Column("radiometric_model", Text),
    Column("status", String(32)),
    Column("min_grade", Float),
    Column("max_grade", Float),
    Column("has_targets", Boolean, nullable=False, default=False),
    Column("has_slew_to_cue", Boolean, nullable=False, default=False),
    Column("coverage", Text),
    Column("source_deleted", Boolean, nullable=False, default=False),
    Column("fingerprint", Text, nullable=False),
    Column("summary", Text),  # the archive's frame summary (path, bytes, digest, band rows) as JSON
    Column("frames_key", Text),  # the session's frames file in the blob store (api.reading.frame_columns)
    Column("indexed_at", BigInteger, nullable=False),
)
Index("ix_sessions_start", sessions.c.start_ns)
Index("ix_sessions_sensor", sessions.c.sensor_id)

segments = Table(
    "segments", metadata,
    Column("session_id", String(128), ForeignKey("sessions.id", ondelete="CASCADE"), primary_key=True),
    Column("name", String(64), primary_key=True),
    Column("frames", Integer, nullable=False),
    Column("bytes", BigInteger, nullable=False),
)

archives = Table(
    "archives", metadata,
    Column("session_id", String(128), ForeignKey("sessions.id", ondelete="CASCADE"), primary_key=True),
    Column("format", String(32), primary_key=True),
    Column("files", Text, nullable=False),
    Column("bytes", BigInteger, nullable=False),
    Column("objects", Integer, nullable=False),
    Column("ratio", Float),
    Column("verified", Boolean, nullable=False),
)

# A session's frames (time, segment, hashes, sidecar summary) are not rows here: they are one
# columnar file in the blob store (api.reading.frame_columns), named by ``sessions.frames_key``.
# What a search across sessions needs is here, a row per second that holds a target: the
# hottest target, the lowest grade, and that second's frames with a target, packed
# (``api.reading.frame_search.HOT_FRAME``), so a camera-hour costs at most 3,600 rows whatever
# the scene, and a search reads no session's file.
target_seconds = Table(
    "target_seconds", metadata,
    Column("session_id", String(128), ForeignKey("sessions.id", ondelete="CASCADE"), primary_key=True),
    Column("second", BigInteger, primary_key=True),  # the frames' log time // 1e9
    Column("max_target_temp_c", Float, nullable=False),
    Column("min_target_temp_c", Float, nullable=False),  # a page's cursor skips the seconds wholly above it
    Column("min_grade", Float),  # over the second's frames with a target that were graded
    Column("frames", LargeBinary, nullable=False),
)
# In the search's own order (hottest first, then session and second): a search walks it from the
# top and stops once no later second can beat the page it holds.
Index("ix_target_seconds_hot", target_seconds.c.max_target_temp_c.desc(), target_seconds.c.session_id,
      target_seconds.c.second)

# Where each frame's image and sidecar sit inside a stored-ZIP archive is not kept here: the
# ZIP's own central directory says it (api.reading.zip_index), so no row per frame per format.
events = Table(
    "events", metadata,
    Column("session_id", String(128), ForeignKey("sessions.id", ondelete="CASCADE"), primary_key=True),
    Column("seq", Integer, primary_key=True),
    Column("kind", String(32), nullable=False),
    Column("start_ns", BigInteger, nullable=False),
    Column("end_ns", BigInteger, nullable=False),
    Column("detail", Text),
)


# Work done on behalf of users and workers (a region series, a session's archive task): what was
# asked, where it stands, how often it was tried and why it failed, so a job's fate never lives
# only in one process's memory or in the Dask dashboard.
jobs = Table(
    "jobs", metadata,
    Column("id", String(96), primary_key=True),
    Column("kind", String(32), nullable=False),
    Column("session_id", String(128)),
    Column("params", Text, nullable=False, default="{}"),
    Column("state", String(16), nullable=False),  # queued, running, done, failed
    Column("attempts", Integer, nullable=False, default=0),
    Column("worker", String(128)),
    Column("error", Text),
    Column("result", Text),  # JSON: small results inline; a large one names its blob
    Column("created_ns", BigInteger, nullable=False),
    Column("started_ns", BigInteger),
    Column("finished_ns", BigInteger),
)
Index("jobs_by_state", jobs.c.state, jobs.c.created_ns)


def make_engine(url: str) -> Engine:
    if url.startswith("sqlite:///"):
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _record) -> None:  # WAL: readers never block the indexer
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.close()

        return engine
    if url.startswith("postgresql://"):
        url = "postgresql+psycopg://" + url.removeprefix("postgresql://")
    return create_engine(url, pool_pre_ping=True)


def migrate(engine: Engine) -> None:
    """Bring the schema to the newest Alembic revision (idempotent, safe on every start)."""
    _run_migrations(engine, "upgrade", "head")


def downgrade(engine: Engine, revision: str) -> None:
    """Take the schema back to ``revision`` (``"0008"``), for an older thermcap: the index has no
    ``alembic.ini`` of its own, its migrations run on a connection handed to them."""
    _run_migrations(engine, "downgrade", revision)


def _run_migrations(engine: Engine, direction: Literal["upgrade", "downgrade"], revision: str) -> None:
    from alembic import command
    from alembic.config import Config
    from sqlalchemy import text

    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).parent / "migrations"))
    with engine.begin() as conn:
        if conn.dialect.name == "postgresql":
            # Workers and API replicas start together: one migrates, the others wait, then see head.
            conn.execute(text("SELECT pg_advisory_xact_lock(7428001)"))
        cfg.attributes["connection"] = conn
        getattr(command, direction)(cfg, revision)
