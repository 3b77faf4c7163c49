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


def upgrade() -> None:
    with op.batch_alter_table("classes") as batch:
        batch.add_column(sa.Column("description", sa.Text(), nullable=True))
        batch.add_column(sa.Column("description_readings", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("classes") as batch:
        batch.drop_column("description_readings")
        batch.drop_column("description")
