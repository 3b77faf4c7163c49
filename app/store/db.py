"""Engine and sessions. SQLite gets WAL and a busy timeout so API processes and
workers can share one file; any other URL is used as given."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

DEFAULT_TIMEOUT_SECONDS = 30.0


def make_engine(url: str, timeout: float = DEFAULT_TIMEOUT_SECONDS) -> Engine:
    """``timeout`` bounds every statement: PostgreSQL's statement_timeout and
    lock_timeout (and the connect timeout), SQLite's busy timeout."""
    ms = max(1, int(timeout * 1000))
    parsed = make_url(url)
    if parsed.drivername == "postgresql":
        # SQLAlchemy 2.1 reads a bare postgresql:// as psycopg 3; the installed driver is psycopg2
        parsed = parsed.set(drivername="postgresql+psycopg2")
    if parsed.get_backend_name() != "sqlite":
        connect_args = {}
        if parsed.get_backend_name() == "postgresql":
            connect_args = {
                "connect_timeout": max(1, int(timeout)),
                "options": f"-c statement_timeout={ms} -c lock_timeout={ms}",
            }
        return create_engine(parsed, pool_pre_ping=True, connect_args=connect_args)
    if parsed.database and parsed.database != ":memory:":
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, connect_args={"check_same_thread": False})
    event.listen(engine, "connect", lambda conn, _record: _sqlite_pragmas(conn, ms))
    return engine


def _sqlite_pragmas(dbapi_conn, busy_ms: int) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")  # readers never block the writer
    cur.execute(f"PRAGMA busy_timeout={busy_ms}")  # wait for the lock, don't fail
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA synchronous=NORMAL")  # durable in WAL mode, much faster commits
    cur.close()


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    # expire_on_commit=False: routes serialise rows after the commit that makes them durable
    return sessionmaker(engine, expire_on_commit=False)


def ping(session: Session) -> None:
    """One round trip to the database; raises ``SQLAlchemyError`` when it does not answer
    (a readiness check)."""
    session.execute(text("SELECT 1"))
