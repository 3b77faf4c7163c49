"""A vocabulary that grows: attributes added through the API, retired ones, graded values
and values not known.

``classes.attribute_key`` holds one token per attribute position, comma-separated: the
value written to 4 decimals without trailing zeros (``1``, ``0``, ``0.5``), or nothing
where the value is not known; trailing unknown positions are left out, so a key keeps its
meaning when attributes are added after it. Existing keys (``0110``) become ``0,1,1,0``.
``attributes`` gains ``origin`` (``dataset`` for every existing row: the bootstrap's
vocabulary, whose values for dataset classes stay fixed; ``enrolled`` for one added through
the API), ``created_at`` and ``retired_at``. Jobs about an attribute have no class:
``jobs.class_id`` becomes nullable and ``jobs.attribute_id`` names the attribute. Each model
version lists the vocabulary it was trained with (``model_versions.attribute_names``);
every existing version was trained with the whole vocabulary of its store.

The downgrade is refused while the store holds anything the older schema cannot read: an
attribute added through the API or retired, a graded value or a value not known, a job
about an attribute.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-24
"""

from __future__ import annotations

import json

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None

UTC_TS = sa.DateTime(timezone=True)
KEY_LENGTH = 2600  # 256 attributes of at most 9 characters each, and their commas


def _columns(table: str) -> set[str]:
    return {c["name"] for c in sa.inspect(op.get_bind()).get_columns(table)}


def _rewrite_keys(convert) -> None:
    bind = op.get_bind()
    rows = bind.execute(sa.text("SELECT id, attribute_key FROM classes")).all()
    for class_id, key in rows:
        new = convert(key)
        if new != key:
            bind.execute(
                sa.text("UPDATE classes SET attribute_key = :k WHERE id = :i"),
                {"k": new, "i": class_id},
            )


def upgrade() -> None:
    bind = op.get_bind()
    op.add_column(
        "attributes",
        sa.Column("origin", sa.String(10), nullable=False, server_default="dataset"),
    )
    op.add_column("attributes", sa.Column("created_at", UTC_TS, nullable=True))
    op.add_column("attributes", sa.Column("retired_at", UTC_TS, nullable=True))
    if bind.dialect.name == "postgresql":  # SQLite does not enforce a VARCHAR's length
        op.alter_column(
            "classes", "attribute_key", type_=sa.String(KEY_LENGTH), existing_nullable=False
        )
    _rewrite_keys(lambda key: ",".join(key))
    with op.batch_alter_table("jobs") as batch:
        batch.alter_column("class_id", existing_type=sa.Integer(), nullable=True)
        batch.add_column(sa.Column("attribute_id", sa.Integer(), nullable=True))
        batch.create_foreign_key(
            "fk_jobs_attribute_id_attributes", "attributes", ["attribute_id"], ["id"]
        )
    op.add_column("model_versions", sa.Column("attribute_names", sa.JSON(), nullable=True))
    names = bind.scalars(sa.text("SELECT name FROM attributes ORDER BY position")).all()
    bind.execute(
        sa.text("UPDATE model_versions SET attribute_names = :names"),
        {"names": json.dumps(list(names))},
    )


def downgrade() -> None:
    bind = op.get_bind()
    # SQLite runs DDL outside the migration's transaction: a step further down that refuses
    # leaves this one's changes made although the revision is still 0007 (see 0005), so
    # each step below is done only where it is still needed
    attributes = _columns("attributes")
    if "origin" in attributes:
        added = bind.scalar(
            sa.text(
                "SELECT COUNT(*) FROM attributes "
                "WHERE origin <> 'dataset' OR retired_at IS NOT NULL"
            )
        )
        if added:
            raise RuntimeError(
                f"cannot downgrade below 0007: {added} attributes were added through the API "
                "or retired, which the older schema's fixed vocabulary cannot hold"
            )
    n = bind.scalar(sa.text("SELECT COUNT(*) FROM attributes"))
    keys = bind.scalars(sa.text("SELECT attribute_key FROM classes WHERE attribute_key <> ''"))
    # a token other than 0 or 1 is graded or not known; a key shorter than the vocabulary
    # ends in values not known
    lossy = [
        k for k in keys if "," in k and (set(k.split(",")) - {"0", "1"} or len(k.split(",")) < n)
    ]
    if lossy:
        raise RuntimeError(
            f"cannot downgrade below 0007: {len(lossy)} classes have graded values or values "
            f"not known (e.g. '{lossy[0]}'), which the older schema stores as 0/1 only"
        )
    if "attribute_id" in _columns("jobs"):
        attribute_jobs = bind.scalar(sa.text("SELECT COUNT(*) FROM jobs WHERE class_id IS NULL"))
        if attribute_jobs:
            raise RuntimeError(
                f"cannot downgrade below 0007: {attribute_jobs} jobs are about attributes"
            )
    _rewrite_keys(lambda key: key.replace(",", ""))
    if "attribute_names" in _columns("model_versions"):
        op.drop_column("model_versions", "attribute_names")
    if "attribute_id" in _columns("jobs"):
        if bind.dialect.name == "sqlite":  # the copy of an attempt whose rename was undone
            op.execute("DROP TABLE IF EXISTS _alembic_tmp_jobs")
        with op.batch_alter_table("jobs") as batch:
            batch.drop_constraint("fk_jobs_attribute_id_attributes", type_="foreignkey")
            batch.drop_column("attribute_id")
            batch.alter_column("class_id", existing_type=sa.Integer(), nullable=False)
    if bind.dialect.name == "postgresql":
        op.alter_column("classes", "attribute_key", type_=sa.String(1000), existing_nullable=False)
    for column in ("retired_at", "created_at", "origin"):
        if column in attributes:
            op.drop_column("attributes", column)
