"""Alembic: upgrade and downgrade, models and migrations agree, any working directory."""

from __future__ import annotations

import threading

from alembic import command
from sqlalchemy import inspect

from app.store import migrate
from app.store.db import make_engine

TABLES = {
    "attributes", "classes", "samples", "bundles", "model_versions", "jobs", "leases", "api_keys",
    "idempotency_keys",
}


def test_upgrade_downgrade_upgrade(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate.upgrade(engine)
    assert migrate.current_revision(engine) == "0002"
    assert TABLES <= set(inspect(engine).get_table_names())
    migrate.downgrade(engine, "base")
    assert migrate.current_revision(engine) is None
    assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
    migrate.upgrade(engine)
    assert TABLES <= set(inspect(engine).get_table_names())
    engine.dispose()


def test_models_match_the_migrations(tmp_path):
    url = f"sqlite:///{tmp_path / 'c.db'}"
    engine = make_engine(url)
    migrate.upgrade(engine)
    command.check(migrate.alembic_config(url))  # raises if autogenerate would find a difference
    engine.dispose()


def test_works_from_any_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    engine = make_engine("sqlite:///relative.db")
    migrate.upgrade(engine)
    assert (tmp_path / "relative.db").exists()
    engine.dispose()


def test_sqlite_is_in_wal_mode_with_a_busy_timeout(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'w.db'}")
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() >= 1000
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    engine.dispose()


def test_concurrent_upgrades_do_not_collide(tmp_path):
    """Two processes starting on an empty store both migrate; the lock serialises them."""
    url = f"sqlite:///{tmp_path / 'race.db'}"
    errors = []

    def run():
        engine = make_engine(url)
        try:
            migrate.upgrade(engine)
        except Exception as exc:  # pragma: no cover - what the test is looking for
            errors.append(exc)
        finally:
            engine.dispose()

    threads = [threading.Thread(target=run) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    engine = make_engine(url)
    assert migrate.current_revision(engine) == "0002"
    engine.dispose()


def test_a_bare_postgresql_url_uses_the_installed_driver():
    engine = make_engine("postgresql://user@db.invalid:5432/tactile")  # no connection is made
    assert engine.url.drivername == "postgresql+psycopg2"
    engine.dispose()
