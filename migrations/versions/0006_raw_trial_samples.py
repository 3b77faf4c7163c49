"""Raw BioTac trials: ``samples.form`` says how ``data`` holds a sample, and
``model_versions.input_kind`` what a version takes; classes registered without a
description (the empty attribute key) are left out of the unique index on vectors.

``array`` (every existing row): float32 bytes of ``shape``, as before. ``raw_trial``: the
trial as a robot sent it (``.npz`` of its fingers' channels, phases and timestamps), kept so
that a later model, with a featurizer fitted again, can featurize it anew. A version takes
``samples`` (every existing one) or ``raw_trials``.

The downgrade is refused while the store holds raw trials: the older schema would read
their bytes as float32 samples.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


INDEX = "uq_classes_live_enrolled_attribute_key"
OLD_WHERE = "origin = 'enrolled' AND withdrawn_at IS NULL"
NEW_WHERE = f"{OLD_WHERE} AND attribute_key <> ''"


def _vector_index(where: str) -> None:
    op.drop_index(INDEX, table_name="classes")
    op.create_index(
        INDEX,
        "classes",
        ["attribute_key"],
        unique=True,
        sqlite_where=sa.text(where),
        postgresql_where=sa.text(where),
    )


def upgrade() -> None:
    # classes registered from samples alone (a model without attributes) have the empty key
    _vector_index(NEW_WHERE)
    op.add_column(
        "samples", sa.Column("form", sa.String(10), nullable=False, server_default="array")
    )
    op.add_column(
        "model_versions",
        sa.Column("input_kind", sa.String(12), nullable=False, server_default="samples"),
    )


def downgrade() -> None:
    bind = op.get_bind()
    # absent when an earlier attempt dropped it and a step further down then refused
    # (SQLite keeps the DDL of a refused downgrade; see 0005)
    if "form" not in {c["name"] for c in sa.inspect(bind).get_columns("samples")}:
        return
    versions = {c["name"] for c in sa.inspect(bind).get_columns("model_versions")}
    raw = bind.scalar(sa.text("SELECT COUNT(*) FROM samples WHERE form = 'raw_trial'"))
    if raw:
        raise RuntimeError(
            f"cannot downgrade below 0006: the store holds {raw} raw-trial samples, which "
            "the older schema would misread as arrays"
        )
    undescribed = bind.scalar(
        sa.text(f"SELECT COUNT(*) FROM classes WHERE {OLD_WHERE} AND attribute_key = ''")
    )
    if undescribed > 1:
        raise RuntimeError(
            f"cannot downgrade below 0006: {undescribed} live classes were registered without "
            "a description, which the older schema's unique index forbids"
        )
    _vector_index(OLD_WHERE)
    if "input_kind" in versions:
        op.drop_column("model_versions", "input_kind")
    op.drop_column("samples", "form")
