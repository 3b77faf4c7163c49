"""Classes described in words: ``classes.description`` keeps the text an operator wrote,
``classes.description_readings`` what was read from it (attribute, value, words, source;
``app.words.interpret``), so a class's values can be traced to its words and a word added
to the vocabulary later can be read from it. Both are empty for classes described by values.

The downgrade drops both columns: the values read stay in ``attribute_key``.

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-25
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


COLUMNS = (("description", sa.Text()), ("description_readings", sa.JSON()))


def _columns() -> set[str]:
    return {c["name"] for c in sa.inspect(op.get_bind()).get_columns("classes")}


# Plain ALTER TABLE on both databases (SQLite adds and, from 3.35, drops columns itself).
# SQLite runs DDL outside the migration's transaction, so a downgrade refused further down
# (0004's check) leaves these columns dropped: each step does only what is not done yet.
def upgrade() -> None:
    present = _columns()
    for name, kind in COLUMNS:
        if name not in present:
            op.add_column("classes", sa.Column(name, kind, nullable=True))


def downgrade() -> None:
    present = _columns()
    for name, _ in reversed(COLUMNS):
        if name in present:
            op.drop_column("classes", name)
