"""PostgreSQL: store bundle bytes without TOAST compression.

Bundles are zip archives whose arrays are already compressed where that pays, so
PostgreSQL's own pglz pass over every new bundle found nothing to gain and cost
about 40 ms of server CPU per enrollment (3.3 MB bundle: insert 85 -> 47 ms).
EXTERNAL keeps out-of-line storage and drops only the compression attempt; rows
already written keep their storage until rewritten. Nothing changes on SQLite.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def _set_storage(kind: str) -> None:
    if op.get_bind().dialect.name == "postgresql":
        op.execute(f"ALTER TABLE bundles ALTER COLUMN data SET STORAGE {kind}")


def upgrade() -> None:
    _set_storage("EXTERNAL")


def downgrade() -> None:
    _set_storage("EXTENDED")
