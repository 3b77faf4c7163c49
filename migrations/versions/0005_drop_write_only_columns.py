"""Drop columns that were written and never read: samples' stored features, jobs' heartbeat.

``samples.features`` and ``samples.features_version`` held each sample's CONV_XF features
under a model version, written at bootstrap and after every retrain, but nothing read
them: a full retrain fits from the samples themselves. ``jobs.heartbeat_at`` was set when a
job was claimed and never renewed nor read: the retrain lease (``app.store.leases``) is
what finds a dead worker, and the next holder re-queues its jobs. Dropping a column copies
no table on PostgreSQL; SQLite (3.35 or later) rewrites the samples table once, without
the feature bytes.

The downgrade adds the three columns back, nullable and empty: the code of revision 0004
writes them and reads none of them.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

UTC_TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.drop_column("jobs", "heartbeat_at")
    op.drop_column("samples", "features_version")
    op.drop_column("samples", "features")


def downgrade() -> None:
    # SQLite runs DDL outside the migration's transaction: when a step further down refuses
    # (0004's, while the store holds withdrawals), the columns added here stay although the
    # revision is still 0005, so the next attempt adds only those still missing
    inspector = sa.inspect(op.get_bind())
    for table, column in (
        ("samples", sa.Column("features", sa.LargeBinary(), nullable=True)),
        ("samples", sa.Column("features_version", sa.Integer(), nullable=True)),
        ("jobs", sa.Column("heartbeat_at", UTC_TS, nullable=True)),
    ):
        if column.name not in {c["name"] for c in inspector.get_columns(table)}:
            op.add_column(table, column)
