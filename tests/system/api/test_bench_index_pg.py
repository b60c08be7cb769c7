"""``thermcap bench index --db`` on a real PostgreSQL: a fresh database made for the run and
dropped after it, the same catalog and search as on SQLite."""

from __future__ import annotations

import json

from sqlalchemy import create_engine, text

from tests.conftest import run_cli


def test_bench_index_on_postgresql(postgres_url):
    r = run_cli("bench", "index", "--sessions", "300", "--frames", "20000", "--db", postgres_url, "--json",
                timeout=600)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["database"] == "postgresql" and res["frame_search_hits_first_page"] > 0
    engine = create_engine(postgres_url.replace("postgresql://", "postgresql+psycopg://", 1))
    with engine.connect() as c:
        left = c.execute(text("SELECT count(*) FROM pg_database WHERE datname LIKE 'thermcap_bench_%'")).scalar()
    assert left == 0  # dropped after the run
