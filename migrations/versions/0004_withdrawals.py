"""Withdrawals: wrongly enrolled classes and samples can be taken out of the model; and
jobs record who asked for them.

``withdrawn_at`` on classes and samples marks them; the rows stay, because jobs and
stored model versions refer to them. A withdrawn class no longer holds its attribute
vector, so the partial unique index on enrolled vectors now covers live classes only.
Only columns are added and one index replaced: no table is copied, so the upgrade is
quick and safe on a store in use.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

UTC_TS = sa.DateTime(timezone=True)
OLD_INDEX, OLD_WHERE = "uq_classes_enrolled_attribute_key", "origin = 'enrolled'"
NEW_INDEX, NEW_WHERE = (
    "uq_classes_live_enrolled_attribute_key",
    "origin = 'enrolled' AND withdrawn_at IS NULL",
)


def _vector_index(name: str, where: str) -> None:
    op.create_index(
        name,
        "classes",
        ["attribute_key"],
        unique=True,
        sqlite_where=sa.text(where),
        postgresql_where=sa.text(where),
    )


def upgrade() -> None:
    op.add_column("classes", sa.Column("withdrawn_at", UTC_TS, nullable=True))
    op.add_column("samples", sa.Column("withdrawn_at", UTC_TS, nullable=True))
    op.add_column("jobs", sa.Column("requested_by", sa.String(length=200), nullable=True))
    op.drop_index(OLD_INDEX, table_name="classes")
    _vector_index(NEW_INDEX, NEW_WHERE)


def downgrade() -> None:
    withdrawn = (
        op.get_bind()
        .execute(
            sa.text(
                "SELECT (SELECT count(*) FROM classes WHERE withdrawn_at IS NOT NULL)"
                " + (SELECT count(*) FROM samples WHERE withdrawn_at IS NOT NULL)"
            )
        )
        .scalar()
    )
    if withdrawn:
        # the older schema cannot say that they were withdrawn: they would come back
        raise RuntimeError(
            f"the store holds {withdrawn} withdrawn classes and samples; revision 0003 cannot "
            "represent them, so the downgrade is refused"
        )
    op.drop_index(NEW_INDEX, table_name="classes")
    _vector_index(OLD_INDEX, OLD_WHERE)
    op.drop_column("jobs", "requested_by")
    op.drop_column("samples", "withdrawn_at")
    op.drop_column("classes", "withdrawn_at")
