"""Alembic environment: runs on the connection app.store.migrate hands over, or on
``sqlalchemy.url`` when called from the ``alembic`` command with ``-x``-free config."""

from __future__ import annotations

from alembic import context
from sqlalchemy import String

from app.store.db import make_engine
from app.store.models import Base

config = context.config
target_metadata = Base.metadata


def _compare_type(ctx, inspected, metadata, inspected_type, metadata_type):
    """SQLite does not enforce a VARCHAR's length, so migrations widen one on PostgreSQL
    only (0007); a length alone is no difference there. Otherwise Alembic's own check."""
    if (
        ctx.dialect.name == "sqlite"
        and isinstance(inspected_type, String)
        and isinstance(metadata_type, String)
    ):
        return False
    return None


def _configure_and_run(**kwargs) -> None:
    # batch mode: SQLite can only alter tables by copying them
    context.configure(
        target_metadata=target_metadata,
        render_as_batch=True,
        compare_type=_compare_type,
        **kwargs,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_offline() -> None:
    _configure_and_run(url=config.get_main_option("sqlalchemy.url"), literal_binds=True)


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _configure_and_run(connection=connection)
        return
    engine = make_engine(config.get_main_option("sqlalchemy.url"))
    try:
        with engine.connect() as conn:
            _configure_and_run(connection=conn)
            conn.commit()
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
