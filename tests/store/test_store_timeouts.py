"""Every database call has a time limit: a statement that waits too long is an error the
API answers with a 503 problem, never a hang."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text
from sqlalchemy.exc import OperationalError

from app.store.db import make_engine
from app.testing.service import unused_vectors
from tests.service_fixtures import postgres_url

PG_URL = postgres_url()


def test_sqlite_busy_timeout_follows_the_setting(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 't.db'}", timeout=2.5)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() == 2500
    engine.dispose()


@pytest.mark.postgres
@pytest.mark.skipif(
    not PG_URL, reason="no PostgreSQL reachable (TACTILE_TEST_POSTGRES_URL or the local server)"
)
def test_postgres_statements_and_lock_waits_are_bounded():
    engine = make_engine(PG_URL, timeout=0.3)
    with engine.connect() as conn:
        assert conn.execute(text("SHOW statement_timeout")).scalar() == "300ms"
        assert conn.execute(text("SHOW lock_timeout")).scalar() == "300ms"
        with pytest.raises(OperationalError):
            conn.execute(text("SELECT pg_sleep(2)"))
    engine.dispose()


def test_a_locked_store_is_a_503_not_a_hang(settings, base_model, dataset):
    from app.api.main import create_app

    app = create_app(
        settings.model_copy(update={"db_timeout_seconds": 0.3}), trainer=lambda: base_model
    )
    body = {"name": "blocked", "attribute_vector": unused_vectors(dataset, 1)[0]}
    with TestClient(app) as client:
        blocker = make_engine(settings.sqlalchemy_url, timeout=30)
        with blocker.connect() as conn:
            if conn.dialect.name == "sqlite":
                conn.exec_driver_sql("BEGIN IMMEDIATE")  # holds the write lock
            else:
                conn.execute(text("BEGIN"))
                conn.execute(text("LOCK TABLE classes IN ACCESS EXCLUSIVE MODE"))
            r = client.post("/v1/classes", json=body)
            conn.rollback()
        blocker.dispose()
        assert r.status_code == 503, r.text
        assert r.headers["content-type"] == "application/problem+json"
        assert r.headers["retry-after"] and "lock" not in r.text.lower()
        assert client.post("/v1/classes", json=body).status_code == 202  # fine once released
