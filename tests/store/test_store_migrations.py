"""Alembic: upgrade and downgrade, models and migrations agree, any working directory."""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Iterator

import pytest
from alembic import command
from sqlalchemy import inspect, text
from sqlalchemy.exc import IntegrityError

from app.store import migrate
from app.store.db import make_engine
from app.testing.service import fresh_postgres_database
from tests.service_fixtures import postgres_url, require_postgres

HEAD = "0010"
PG_URL = postgres_url()

TABLES = {
    "attributes",
    "classes",
    "samples",
    "bundles",
    "model_versions",
    "jobs",
    "leases",
    "api_keys",
    "idempotency_keys",
}


def test_upgrade_downgrade_upgrade(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate.upgrade(engine)
    assert migrate.current_revision(engine) == HEAD
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


def test_going_below_0004_is_refused_while_the_store_holds_withdrawals(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'w.db'}")
    migrate.upgrade(engine)
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO classes (name, kind, origin, attribute_key, created_at, withdrawn_at) "
                "VALUES ('mug', 'novel', 'enrolled', '', '2026-11-23', '2026-11-23')"
            )
        )
    with pytest.raises(RuntimeError, match="1 withdrawn classes and samples"):
        migrate.downgrade(engine, "0003")
    assert migrate.current_revision(engine) == HEAD
    assert "withdrawn_at" in {c["name"] for c in inspect(engine).get_columns("classes")}
    with engine.begin() as conn:
        conn.execute(text("DELETE FROM classes"))
    migrate.downgrade(engine, "0003")
    assert "withdrawn_at" not in {c["name"] for c in inspect(engine).get_columns("classes")}
    engine.dispose()


@contextlib.contextmanager
def _database(backend: str, tmp_path) -> Iterator[str]:
    """The URL of an empty SQLite file or of a fresh PostgreSQL database."""
    if backend == "sqlite":
        yield f"sqlite:///{tmp_path / 'd.db'}"
        return
    with fresh_postgres_database(require_postgres()) as url:
        yield url


def _insert_version(conn, **columns: str) -> None:
    """Model version 1 and its bundle, as a store of an older revision holds them;
    ``columns``: more columns of model_versions, as SQL literals."""
    conn.execute(
        text(
            "INSERT INTO bundles (sha256, size, data, created_at) "
            "VALUES ('ab', 1, :d, '2026-11-24')"
        ),
        {"d": b"x"},
    )
    names = ", ".join(
        [
            "version",
            "created_at",
            "method",
            "reason",
            "bundle_sha256",
            "input_shape",
            "metrics",
            "classes",
            "sample_ids",
            "active",
            *columns,
        ]
    )
    values = ", ".join(
        [
            "1",
            "'2026-11-24'",
            "'best'",
            "'bootstrap'",
            "'ab'",
            "'[2]'",
            "'{}'",
            "'[]'",
            "'[]'",
            "false",
            *columns.values(),
        ]
    )
    conn.execute(text(f"INSERT INTO model_versions ({names}) VALUES ({values})"))


def _columns(engine, table: str) -> dict[str, dict]:
    return {c["name"]: c for c in inspect(engine).get_columns(table)}


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_0005_drops_the_write_only_columns_and_keeps_every_row(backend, tmp_path):
    """Samples' stored features and jobs' heartbeat go; the rows stay. Going back down adds
    the columns again, nullable and empty."""
    with _database(backend, tmp_path) as url:
        engine = make_engine(url)
        migrate.upgrade(engine, "0004")
        with engine.begin() as conn:
            conn.execute(
                text(
                    "INSERT INTO classes (id, name, kind, origin, attribute_key, created_at) "
                    "VALUES (1, 'mug', 'novel', 'enrolled', '01', '2026-11-23')"
                )
            )
            conn.execute(
                text(
                    "INSERT INTO samples (id, class_id, origin, shape, data, features, "
                    "features_version, created_at) VALUES (1, 1, 'enrolled', '[2]', :data, "
                    ":features, 3, '2026-11-23')"
                ),
                {"data": b"12345678", "features": b"feat"},
            )
            conn.execute(
                text(
                    "INSERT INTO jobs (id, kind, status, class_id, sample_id, heartbeat_at, "
                    "created_at) VALUES (1, 'add_sample', 'running', 1, 1, '2026-11-23', "
                    "'2026-11-23')"
                )
            )
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == HEAD
        assert not {"features", "features_version"} & set(_columns(engine, "samples"))
        assert "heartbeat_at" not in _columns(engine, "jobs")
        with engine.connect() as conn:
            sample_id, data = conn.execute(text("SELECT id, data FROM samples")).one()
            assert (sample_id, bytes(data)) == (1, b"12345678")  # psycopg2 gives a memoryview
            assert conn.execute(text("SELECT id, status FROM jobs")).one() == (1, "running")
        migrate.downgrade(engine, "0004")
        samples, jobs = _columns(engine, "samples"), _columns(engine, "jobs")
        assert samples["features"]["nullable"] and samples["features_version"]["nullable"]
        assert jobs["heartbeat_at"]["nullable"]
        with engine.connect() as conn:
            data, *dropped = conn.execute(
                text("SELECT data, features, features_version FROM samples")
            ).one()
            assert bytes(data) == b"12345678" and dropped == [None, None]
            assert conn.execute(text("SELECT heartbeat_at FROM jobs")).scalar() is None
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
    assert migrate.current_revision(engine) == HEAD
    engine.dispose()


def test_a_bare_postgresql_url_uses_the_installed_driver():
    engine = make_engine("postgresql://user@db.invalid:5432/tactile")  # no connection is made
    assert engine.url.drivername == "postgresql+psycopg2"
    engine.dispose()


@pytest.mark.postgres
@pytest.mark.skipif(
    not PG_URL, reason="no PostgreSQL reachable (TACTILE_TEST_POSTGRES_URL or the local server)"
)
def test_postgresql_upgrade_downgrade_and_bundle_storage():
    """Bundles (already compressed) skip TOAST compression on PostgreSQL; the whole chain
    also goes down and up again there."""

    def bundle_storage(engine) -> str:
        with engine.connect() as conn:
            return conn.execute(
                text(
                    "SELECT attstorage FROM pg_attribute "
                    "WHERE attrelid = 'bundles'::regclass AND attname = 'data'"
                )
            ).scalar()

    with fresh_postgres_database(PG_URL) as url:
        engine = make_engine(url)
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == HEAD
        assert bundle_storage(engine) == "e"  # EXTERNAL
        migrate.downgrade(engine, "0002")
        assert bundle_storage(engine) == "x"  # EXTENDED, PostgreSQL's default for bytea
        migrate.downgrade(engine, "base")
        assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
        migrate.upgrade(engine)
        assert TABLES <= set(inspect(engine).get_table_names()) and bundle_storage(engine) == "e"
        engine.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_0006_marks_every_sample_an_array_and_refuses_to_drop_raw_trials(backend, tmp_path):
    with _database(backend, tmp_path) as url:
        engine = make_engine(url)
        migrate.upgrade(engine, "0005")
        with engine.begin() as conn:
            conn.execute(
                text(
                    "INSERT INTO classes (name, kind, origin, attribute_key, created_at) "
                    "VALUES ('mug', 'known', 'dataset', '01', '2026-11-24')"
                )
            )
            conn.execute(
                text(
                    "INSERT INTO samples (class_id, origin, shape, data, created_at) "
                    "VALUES (1, 'dataset', '[2]', :data, '2026-11-24')"
                ),
                {"data": b"\0" * 8},
            )
        migrate.upgrade(engine)
        with engine.connect() as conn:
            assert conn.execute(text("SELECT form FROM samples")).scalars().all() == ["array"]
        with engine.begin() as conn:
            conn.execute(text("UPDATE samples SET form = 'raw_trial'"))
        with pytest.raises(RuntimeError, match="1 raw-trial samples"):
            migrate.downgrade(engine, "0005")
        assert migrate.current_revision(engine) == HEAD and "form" in _columns(engine, "samples")
        with engine.begin() as conn:
            conn.execute(text("UPDATE samples SET form = 'array'"))
        migrate.downgrade(engine, "0005")
        assert "form" not in _columns(engine, "samples")
        with engine.connect() as conn:
            assert conn.execute(text("SELECT COUNT(*) FROM samples")).scalar() == 1
        engine.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_0007_rewrites_keys_lists_each_versions_vocabulary_and_refuses_to_lose_values(
    backend, tmp_path
):
    with _database(backend, tmp_path) as url:
        engine = make_engine(url)
        migrate.upgrade(engine, "0006")
        with engine.begin() as conn:
            for i, name in enumerate(("hard", "soft", "warm")):
                conn.execute(
                    text("INSERT INTO attributes (position, name) VALUES (:p, :n)"),
                    {"p": i, "n": name},
                )
            conn.execute(
                text(
                    "INSERT INTO classes (name, kind, origin, attribute_key, created_at) "
                    "VALUES ('mug', 'known', 'dataset', '101', '2026-11-24')"
                )
            )
            _insert_version(conn)
        migrate.upgrade(engine)
        with engine.connect() as conn:
            assert conn.execute(text("SELECT attribute_key FROM classes")).scalar() == "1,0,1"
            names = conn.execute(text("SELECT attribute_names FROM model_versions")).scalar()
            names = json.loads(names) if isinstance(names, str) else names
            assert names == ["hard", "soft", "warm"]
            origins = conn.execute(text("SELECT DISTINCT origin FROM attributes")).scalars()
            assert list(origins) == ["dataset"]
        with engine.begin() as conn:  # a graded value the older schema cannot hold
            conn.execute(text("UPDATE classes SET attribute_key = '1,0.5,1'"))
        with pytest.raises(RuntimeError, match="graded values or values not known"):
            migrate.downgrade(engine, "0006")
        assert migrate.current_revision(engine) == HEAD
        with engine.begin() as conn:  # an attribute added through the API
            conn.execute(text("UPDATE classes SET attribute_key = '1,0,1'"))
            conn.execute(
                text("INSERT INTO attributes (position, name, origin) VALUES (3, 'x', 'enrolled')")
            )
        with pytest.raises(RuntimeError, match="1 attributes were added through the API"):
            migrate.downgrade(engine, "0006")
        with engine.begin() as conn:
            conn.execute(text("DELETE FROM attributes WHERE name = 'x'"))
        migrate.downgrade(engine, "0006")
        with engine.connect() as conn:
            assert conn.execute(text("SELECT attribute_key FROM classes")).scalar() == "101"
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == HEAD
        engine.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_0009_adds_procedures_to_model_versions_and_keeps_every_row(backend, tmp_path):
    with _database(backend, tmp_path) as url:
        engine = make_engine(url)
        migrate.upgrade(engine, "0008")
        with engine.begin() as conn:
            _insert_version(conn, attribute_names="'[]'")
        migrate.upgrade(engine)
        assert {"procedures", "first_procedure"} <= set(_columns(engine, "model_versions"))
        with engine.connect() as conn:
            row = conn.execute(
                text("SELECT version, procedures, first_procedure FROM model_versions")
            )
            assert tuple(row.one()) == (1, None, None)  # stored before: no procedures named
        migrate.downgrade(engine, "0008")
        assert not {"procedures", "first_procedure"} & set(_columns(engine, "model_versions"))
        with engine.connect() as conn:
            assert conn.execute(text("SELECT count(*) FROM model_versions")).scalar() == 1
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == HEAD
        engine.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_0010_folds_class_names_and_keeps_names_that_already_differ_only_in_case(backend, tmp_path):
    with _database(backend, tmp_path) as url:
        engine = make_engine(url)
        migrate.upgrade(engine, "0009")
        with engine.begin() as conn:
            for name in ("Foam-Block", "foam-block", "mug"):
                conn.execute(
                    text(
                        "INSERT INTO classes (name, kind, origin, attribute_key, created_at) "
                        "VALUES (:n, 'novel', 'enrolled', '', '2026-11-28')"
                    ),
                    {"n": name},
                )
        migrate.upgrade(engine)
        with engine.connect() as conn:
            keys = dict(conn.execute(text("SELECT name, name_key FROM classes")).all())
        # the oldest of each folded name holds it; the later one keeps its row, unkeyed
        assert keys == {"Foam-Block": "foam-block", "foam-block": None, "mug": "mug"}
        assert "warnings" in set(_columns(engine, "jobs"))
        with pytest.raises(IntegrityError), engine.begin() as conn:
            conn.execute(
                text(
                    "INSERT INTO classes (name, name_key, kind, origin, attribute_key, "
                    "created_at) VALUES ('MUG', 'mug', 'novel', 'enrolled', '', '2026-11-28')"
                )
            )
        migrate.downgrade(engine, "0009")
        assert "name_key" not in set(_columns(engine, "classes"))
        assert "warnings" not in set(_columns(engine, "jobs"))
        with engine.connect() as conn:
            assert conn.execute(text("SELECT count(*) FROM classes")).scalar() == 3
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == HEAD
        engine.dispose()
