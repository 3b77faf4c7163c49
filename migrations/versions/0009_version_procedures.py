"""Model versions name their exploratory procedures: ``model_versions.procedures`` (the
procedures a sample holds, in order) and ``model_versions.first_procedure`` (the one to do
first, where the model answers samples that lack some). Both are null for versions stored
before; ``GET /v1/models`` then lists no procedures.

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-25
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


COLUMNS = (("procedures", sa.JSON()), ("first_procedure", sa.String(200)))


def _columns() -> set[str]:
    return {c["name"] for c in sa.inspect(op.get_bind()).get_columns("model_versions")}


# SQLite runs DDL outside the migration's transaction: each step does only what is not
# done yet, so a downgrade refused further down can be run again.
def upgrade() -> None:
    present = _columns()
    for name, kind in COLUMNS:
        if name not in present:
            op.add_column("model_versions", sa.Column(name, kind, nullable=True))


def downgrade() -> None:
    present = _columns()
    for name, _ in reversed(COLUMNS):
        if name in present:
            op.drop_column("model_versions", name)
