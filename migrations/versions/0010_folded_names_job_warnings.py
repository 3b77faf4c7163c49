"""Class names are unique without regard to case and surrounding spaces:
``classes.name_key`` holds each name folded (``app.store.models.fold_name``) under a unique
index, so 'Foam-Block' cannot be registered beside 'foam-block', on SQLite and PostgreSQL
alike (their own ``lower()`` differ beyond ASCII). ``jobs.warnings`` keeps what the request
that queued a job was warned of (a sample the served model gave to another class).

A store that already holds names differing only in case keeps them: the oldest class of
each folded name gets the key, the others none (the migration logs them), and every later
registration is compared with the one keyed. The downgrade drops both columns.

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-28
"""

from __future__ import annotations

import logging

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None

log = logging.getLogger("alembic.runtime.migration")

INDEX = "uq_classes_name_key"


def fold_name(name: str) -> str:
    """``app.store.models.fold_name`` as this revision wrote the keys."""
    return name.strip().casefold()


def _columns(table: str) -> set[str]:
    return {c["name"] for c in sa.inspect(op.get_bind()).get_columns(table)}


def _indexes() -> set[str]:
    return {i["name"] for i in sa.inspect(op.get_bind()).get_indexes("classes")}


# SQLite runs DDL outside the migration's transaction: each step does only what is not
# done yet, so a migration cut short can be run again.
def upgrade() -> None:
    bind = op.get_bind()
    if "name_key" not in _columns("classes"):
        op.add_column("classes", sa.Column("name_key", sa.String(800), nullable=True))
    classes = sa.table("classes", sa.column("id"), sa.column("name"), sa.column("name_key"))
    keyed: dict[str, str] = {}  # folded name -> the name that holds it
    for cid, name in bind.execute(sa.select(classes.c.id, classes.c.name).order_by("id")):
        key: str | None = fold_name(name)
        if key in keyed:
            log.warning(
                "class %r (id %s) keeps its name beside %r, which differs only in case; "
                "later names are compared with %r",
                name,
                cid,
                keyed[key],
                keyed[key],
            )
            key = None
        else:
            keyed[key] = name
        bind.execute(sa.update(classes).where(classes.c.id == cid).values(name_key=key))
    if INDEX not in _indexes():
        op.create_index(INDEX, "classes", ["name_key"], unique=True)
    if "warnings" not in _columns("jobs"):
        op.add_column("jobs", sa.Column("warnings", sa.JSON(), nullable=True))


def downgrade() -> None:
    if "warnings" in _columns("jobs"):
        op.drop_column("jobs", "warnings")
    if INDEX in _indexes():
        op.drop_index(INDEX, table_name="classes")
    if "name_key" in _columns("classes"):
        op.drop_column("classes", "name_key")
