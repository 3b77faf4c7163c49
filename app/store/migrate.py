"""Alembic, configured in code: no alembic.ini, works from any working directory."""

from __future__ import annotations

import contextlib
import fcntl
from collections.abc import Iterator
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import Connection, Engine, text

import migrations

# any constant: the PostgreSQL advisory lock that serialises concurrent upgrades
_PG_LOCK_KEY = 0x7AC7_11E5


def alembic_config(url: str) -> Config:
    cfg = Config()
    # __path__, not __file__: also right when the package is installed as a namespace
    cfg.set_main_option("script_location", str(Path(list(migrations.__path__)[0]).resolve()))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))  # ConfigParser escapes %
    return cfg


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Bring the schema to ``revision``; safe when several processes start at once."""
    _run(engine, lambda cfg: command.upgrade(cfg, revision))


def downgrade(engine: Engine, revision: str) -> None:
    _run(engine, lambda cfg: command.downgrade(cfg, revision))


def current_revision(engine: Engine) -> str | None:
    from alembic.runtime.migration import MigrationContext

    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def _run(engine: Engine, action) -> None:
    cfg = alembic_config(engine.url.render_as_string(hide_password=False))
    with _exclusive(engine), engine.begin() as conn:
        _lock_connection(conn)
        cfg.attributes["connection"] = conn
        action(cfg)


def _lock_connection(conn: Connection) -> None:
    if conn.dialect.name == "postgresql":
        conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PG_LOCK_KEY})


@contextlib.contextmanager
def _exclusive(engine: Engine) -> Iterator[None]:
    """SQLite runs DDL outside transactions, so a file lock beside the database
    keeps two processes from both creating the tables."""
    db = engine.url.database if engine.dialect.name == "sqlite" else None
    if not db or db == ":memory:":
        yield
        return
    with open(f"{db}.migrate.lock", "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
