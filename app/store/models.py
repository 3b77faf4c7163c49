"""SQLAlchemy 2 models: the store every API process and worker shares.

Portable between SQLite and PostgreSQL: no dialect-specific column types; the
two partial unique indexes are supported by both.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    TypeDecorator,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, query_expression

from app.store.enums import JobStatus, Origin, SampleForm

# Stable constraint names so Alembic migrations (and SQLite batch mode) can refer to them.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class UTCDateTime(TypeDecorator):
    """Timezone-aware UTC datetimes on every backend (SQLite returns naive ones)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value.astimezone(UTC) if value is not None else None

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)


class Attribute(Base):
    """The attribute vocabulary; ``position`` is the attribute's token in class keys
    (``app.store.vocabulary``). Names are never reused, retired ones included, so a model
    version's vocabulary keeps its meaning."""

    __tablename__ = "attributes"

    id: Mapped[int] = mapped_column(primary_key=True)
    position: Mapped[int] = mapped_column(Integer, unique=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    # the bootstrap dataset's (its values for the dataset's classes stay fixed) or enrolled
    origin: Mapped[str] = mapped_column(
        String(10), default=Origin.DATASET, server_default=Origin.DATASET.value
    )
    created_at: Mapped[datetime | None] = mapped_column(UTCDateTime, default=utcnow)
    # set when an operator retires it: later models leave it out, older versions keep it
    retired_at: Mapped[datetime | None] = mapped_column(UTCDateTime)


LIVE_ENROLLED = f"origin = '{Origin.ENROLLED}' AND withdrawn_at IS NULL"
# classes registered without a description (a model without attributes) share the empty key
DESCRIBED_LIVE_ENROLLED = f"{LIVE_ENROLLED} AND attribute_key <> ''"


def fold_name(name: str) -> str:
    """A class name as names are compared: without regard to case and surrounding spaces
    ('Foam-Block ' is 'foam-block')."""
    return name.strip().casefold()


def _name_key(context: Any) -> str:
    return fold_name(context.get_current_parameters()["name"])


class ObjectClass(Base):
    __tablename__ = "classes"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    # fold_name(name), unique: 'Foam-Block' cannot join 'foam-block'. Null only for a class
    # that already shared its folded name with an older one when migration 0010 ran.
    name_key: Mapped[str | None] = mapped_column(String(800), default=_name_key)
    kind: Mapped[str] = mapped_column(String(10))  # ClassKind
    origin: Mapped[str] = mapped_column(String(10))  # Origin
    # the description, one token per attribute position: "1,0,0.5,,1" (app.store.vocabulary)
    attribute_key: Mapped[str] = mapped_column(String(2600), index=True)
    # a description in words, and what was read from it (app.words.interpret)
    description: Mapped[str | None] = mapped_column(Text)
    description_readings: Mapped[list | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    promoted_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # set when an operator withdraws a wrongly enrolled class: it leaves every later
    # model; the row stays for the jobs and model versions that name it
    withdrawn_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    __table_args__ = (
        Index("uq_classes_name_key", "name_key", unique=True),
        # Two concurrent registrations of one vector cannot both commit; dataset
        # classes are exempt because real datasets may repeat a vector, a withdrawn
        # class no longer holds its vector, and classes without one have nothing to share.
        Index(
            "uq_classes_live_enrolled_attribute_key",
            "attribute_key",
            unique=True,
            sqlite_where=text(DESCRIBED_LIVE_ENROLLED),
            postgresql_where=text(DESCRIBED_LIVE_ENROLLED),
        ),
    )


class Sample(Base):
    """A real tactile sample: float32 bytes in C order with their shape, or a raw BioTac
    trial as it was sent (``form``), which a later model can featurize again."""

    __tablename__ = "samples"

    id: Mapped[int] = mapped_column(primary_key=True)
    class_id: Mapped[int] = mapped_column(ForeignKey("classes.id"), index=True)
    origin: Mapped[str] = mapped_column(String(10))  # Origin
    trial: Mapped[int | None] = mapped_column(Integer)  # dataset trial id, for grouped splits
    shape: Mapped[list[int]] = mapped_column(JSON)  # [] for a raw trial
    data: Mapped[bytes] = mapped_column(LargeBinary)
    form: Mapped[str] = mapped_column(
        String(10), default=SampleForm.ARRAY, server_default=SampleForm.ARRAY.value
    )  # SampleForm
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    withdrawn_at: Mapped[datetime | None] = mapped_column(UTCDateTime)  # see ObjectClass


class Bundle(Base):
    """Model bundle bytes, content-addressed so any process on any host can load them."""

    __tablename__ = "bundles"

    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    size: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


class ModelVersion(Base):
    __tablename__ = "model_versions"

    version: Mapped[int] = mapped_column(primary_key=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    method: Mapped[str] = mapped_column(String(100))
    reason: Mapped[str] = mapped_column(String(20))  # VersionReason
    base_version: Mapped[int | None] = mapped_column(Integer)
    bundle_sha256: Mapped[str] = mapped_column(ForeignKey("bundles.sha256"))
    input_shape: Mapped[list[int]] = mapped_column(JSON)
    # what the version takes: "samples" of input_shape, or "raw_trials" (its featurizer makes
    # input_shape images of them)
    input_kind: Mapped[str] = mapped_column(String(12), default="samples", server_default="samples")
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # the attribute vocabulary the version was trained with, in its vectors' order
    attribute_names: Mapped[list[str] | None] = mapped_column(JSON)
    # the exploratory procedures a sample holds, and the one to do first (None: the model
    # answers complete samples only); null for versions stored before they were kept
    procedures: Mapped[list[str] | None] = mapped_column(JSON)
    first_procedure: Mapped[str | None] = mapped_column(String(200))
    classes: Mapped[list[dict[str, Any]]] = mapped_column(JSON)  # [{"name", "kind"}]
    sample_ids: Mapped[list[int]] = mapped_column(JSON, default=list)  # enrolled samples inside
    active: Mapped[bool] = mapped_column(Boolean, default=False)
    # filled by repo.list_versions(summary=True), which leaves the class list itself unread
    counted_classes: Mapped[int | None] = query_expression()

    @property
    def class_count(self) -> int:
        return self.counted_classes if self.counted_classes is not None else len(self.classes)

    __table_args__ = (
        # at most one active version, enforced by the database itself
        Index(
            "uq_model_versions_one_active",
            "active",
            unique=True,
            sqlite_where=text("active"),
            postgresql_where=text("active"),
        ),
    )


class Job(Base):
    """One enrollment waiting for (or folded into) a model version.

    Workers claim queued rows (``SELECT … FOR UPDATE SKIP LOCKED`` on PostgreSQL) and
    record themselves in ``claimed_by``. Jobs left ``running`` by a worker that died go back
    to the queue when the next worker takes the retrain lease (``app.store.leases``), which
    only one worker holds at a time (``repo.requeue_running``).
    """

    __tablename__ = "jobs"

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(20))  # JobKind
    status: Mapped[str] = mapped_column(String(10), default=JobStatus.QUEUED)  # JobStatus
    # the class the job is about; None for a job about an attribute (attribute_id)
    class_id: Mapped[int | None] = mapped_column(ForeignKey("classes.id"), index=True)
    sample_id: Mapped[int | None] = mapped_column(ForeignKey("samples.id"))
    attribute_id: Mapped[int | None] = mapped_column(ForeignKey("attributes.id"))
    model_version: Mapped[int | None] = mapped_column(Integer)
    error: Mapped[str | None] = mapped_column(Text)
    # the principal that queued it: key:<id>, env:<hash prefix> or addr:<ip> (keys.Principal)
    requested_by: Mapped[str | None] = mapped_column(String(200))
    claimed_by: Mapped[str | None] = mapped_column(String(200))
    # what the request that queued it was warned of (app.service.enrolment), e.g. a sample
    # the served model gave to another class with high confidence; null: none
    warnings: Mapped[list[str] | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    __table_args__ = (Index("ix_jobs_status_id", "status", "id"),)


class Lease(Base):
    """A named lock with an expiry: bootstrap, and the one retrain at a time."""

    __tablename__ = "leases"

    name: Mapped[str] = mapped_column(String(100), primary_key=True)
    holder: Mapped[str] = mapped_column(String(200))
    expires_at: Mapped[datetime] = mapped_column(UTCDateTime)


class ApiKey(Base):
    """An API key: only its SHA-256 is stored; the key itself is shown once, at creation."""

    __tablename__ = "api_keys"

    id: Mapped[int] = mapped_column(primary_key=True)
    key_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    prefix: Mapped[str] = mapped_column(String(16))  # the first characters, to tell keys apart
    scope: Mapped[str] = mapped_column(String(10))  # read | enroll | admin
    name: Mapped[str | None] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    revoked_at: Mapped[datetime | None] = mapped_column(UTCDateTime)


class IdempotencyRecord(Base):
    """The answer given to one ``Idempotency-Key``, committed with the enrollment it made.

    ``principal`` keeps two clients' keys apart; ``fingerprint`` (SHA-256 of method,
    path and body) tells a retry from a different request reusing the key.
    """

    __tablename__ = "idempotency_keys"

    principal: Mapped[str] = mapped_column(String(64), primary_key=True)
    key: Mapped[str] = mapped_column(String(200), primary_key=True)
    fingerprint: Mapped[str] = mapped_column(String(64))
    status_code: Mapped[int] = mapped_column(Integer)
    body: Mapped[dict[str, Any]] = mapped_column(JSON)
    location: Mapped[str | None] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, index=True)
