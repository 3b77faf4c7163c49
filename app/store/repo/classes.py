"""Repository functions: every query the API and the worker make, in one place.

Functions take a Session and leave committing to the caller unless their name
says otherwise, so one request or one retrain is one transaction.
"""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import LargeBinary, Row, Select, delete, func, insert, select, update
from sqlalchemy.orm import Session, aliased, defer, with_expression

from app.framework.errors import BundleError
from app.store.models import (
    ApiKey,
    Attribute,
    Bundle,
    IdempotencyRecord,
    Job,
    ModelVersion,
    ObjectClass,
    Sample,
    utcnow,
)

# ------------------------------------------------------------------ encoding


def vector_key(vector: Iterable[float]) -> str:
    """A 0/1 attribute vector as a string of digits: comparable and indexable."""
    return "".join("1" if v >= 0.5 else "0" for v in vector)


def key_vector(key: str) -> np.ndarray:
    return np.array([c == "1" for c in key], dtype=np.float32)


def encode_sample(sample: np.ndarray) -> tuple[bytes, list[int]]:
    x = np.ascontiguousarray(sample, dtype=np.float32)
    return x.tobytes(), list(x.shape)


def decode_sample(data: bytes, shape: Sequence[int]) -> np.ndarray:
    return np.frombuffer(data, dtype=np.float32).reshape(tuple(shape))


# ---------------------------------------------------------------- attributes


def attribute_names(session: Session) -> list[str]:
    return list(session.scalars(select(Attribute.name).order_by(Attribute.position)))


def add_attributes(session: Session, names: Sequence[str]) -> None:
    session.add_all(Attribute(position=i, name=n) for i, n in enumerate(names))


def attribute_labels(key: str, vocabulary: Sequence[str]) -> list[str]:
    return [name for name, bit in zip(vocabulary, key, strict=False) if bit == "1"]


# ------------------------------------------------------------------- classes


LIVE_CLASS = ObjectClass.withdrawn_at.is_(None)
LIVE_SAMPLE = Sample.withdrawn_at.is_(None)


def get_class(session: Session, class_id: int) -> ObjectClass | None:
    """The class, unless it does not exist or was withdrawn."""
    cls = session.get(ObjectClass, class_id)
    return cls if cls is not None and cls.withdrawn_at is None else None


def class_by_name(session: Session, name: str, withdrawn: bool = False) -> ObjectClass | None:
    """The live class of that name; with ``withdrawn``, the withdrawn one (names are unique
    over both, so a withdrawn class's name comes back with its row)."""
    state = ObjectClass.withdrawn_at.is_not(None) if withdrawn else LIVE_CLASS
    return session.scalar(select(ObjectClass).where(ObjectClass.name == name, state))


def class_by_key(session: Session, key: str, other_than: int | None = None) -> ObjectClass | None:
    """A live class described by ``key`` (other than class ``other_than``)."""
    stmt = select(ObjectClass).where(ObjectClass.attribute_key == key, LIVE_CLASS)
    if other_than is not None:
        stmt = stmt.where(ObjectClass.id != other_than)
    return session.scalar(stmt.limit(1))


def list_classes(session: Session, after: int | None = None, limit: int | None = None) -> list[ObjectClass]:
    """Live classes by id; with ``after``, those after it; at most ``limit``."""
    stmt = select(ObjectClass).where(LIVE_CLASS).order_by(ObjectClass.id).limit(limit)
    return list(session.scalars(stmt if after is None else stmt.where(ObjectClass.id > after)))


def sample_counts(session: Session, class_ids: Sequence[int] | None = None) -> dict[int, int]:
    """Live samples per class."""
    stmt = select(Sample.class_id, func.count()).where(LIVE_SAMPLE).group_by(Sample.class_id)
    if class_ids is not None:
        stmt = stmt.where(Sample.class_id.in_(class_ids))
    return {cid: n for cid, n in session.execute(stmt)}


def class_ids_by_name(session: Session) -> dict[str, int]:
    return {name: cid for cid, name in session.execute(
        select(ObjectClass.id, ObjectClass.name).where(LIVE_CLASS))}


def add_class(
    session: Session, name: str, key: str, kind: str = "novel", origin: str = "enrolled"
) -> ObjectClass:
    obj = ObjectClass(name=name, kind=kind, origin=origin, attribute_key=key)
    session.add(obj)
    session.flush()
    return obj


# ------------------------------------------------------------------- samples


def add_sample(
    session: Session, class_id: int, sample: np.ndarray, origin: str = "enrolled"
) -> Sample:
    data, shape = encode_sample(sample)
    row = Sample(class_id=class_id, origin=origin, shape=shape, data=data)
    session.add(row)
    session.flush()
    return row


def add_dataset_samples(
    session: Session, class_ids: Sequence[int], samples: np.ndarray, trials: Sequence[int],
    features: np.ndarray | None = None, version: int | None = None,
) -> None:
    """Bulk insert (one executemany) of a whole training set."""
    now = utcnow()
    rows = []
    for i, (cid, x, trial) in enumerate(zip(class_ids, samples, trials, strict=True)):
        data, shape = encode_sample(x)
        feats = None if features is None else encode_sample(features[i])[0]
        rows.append(
            {"class_id": int(cid), "origin": "dataset", "trial": int(trial), "shape": shape,
             "data": data, "features": feats, "features_version": version, "created_at": now}
        )
    if rows:
        session.execute(insert(Sample), rows)


def samples_of(session: Session, class_ids: Sequence[int]) -> list[Sample]:
    """The live samples of these classes, by id."""
    stmt = select(Sample).where(Sample.class_id.in_(class_ids), LIVE_SAMPLE).order_by(Sample.id)
    return list(session.scalars(stmt))


def list_samples(
    session: Session, class_id: int, after: int | None = None, limit: int | None = None
) -> list[Row]:
    """Rows of ``id, origin, trial, created_at, enrolled_by`` (who added it) of the class's
    live samples by id; the sample data stay unread."""
    stmt = _live_samples(class_id).order_by(Sample.id).limit(limit)
    if after is not None:
        stmt = stmt.where(Sample.id > after)
    return list(session.execute(stmt))


def sample_record(session: Session, class_id: int, sample_id: int) -> Row | None:
    """The ``list_samples`` row of one live sample, with its ``shape`` and ``data``."""
    stmt = _live_samples(class_id, Sample.shape, Sample.data).where(Sample.id == sample_id)
    return session.execute(stmt).first()


def _live_samples(class_id: int, *columns: Any) -> Select:
    enrolment = aliased(Job)
    return (
        select(Sample.id, Sample.origin, Sample.trial, Sample.created_at,
               enrolment.requested_by.label("enrolled_by"), *columns)
        .outerjoin(enrolment, (enrolment.sample_id == Sample.id) & (enrolment.kind == "add_sample"))
        .where(Sample.class_id == class_id, LIVE_SAMPLE)
    )


def get_sample(session: Session, class_id: int, sample_id: int) -> Sample | None:
    """The live sample ``sample_id`` of class ``class_id`` (its data left unread)."""
    row = session.get(Sample, sample_id, options=[defer(Sample.data), defer(Sample.features)])
    live = row is not None and row.class_id == class_id and row.withdrawn_at is None
    return row if live else None


# --------------------------------------------------------------- withdrawals


def withdraw_class(session: Session, cls: ObjectClass) -> None:
    """The class and its samples leave every later model (the worker's next round)."""
    now = utcnow()
    cls.withdrawn_at = now
    session.execute(
        update(Sample).where(Sample.class_id == cls.id, LIVE_SAMPLE).values(withdrawn_at=now)
    )
    session.flush()


def withdraw_sample(session: Session, row: Sample) -> None:
    row.withdrawn_at = utcnow()
    session.flush()


def redescribe_class(session: Session, cls: ObjectClass, key: str) -> None:
    """New attributes for a live class; its samples stay (the worker's next round)."""
    cls.attribute_key = key
    session.flush()


def revive_class(session: Session, cls: ObjectClass, key: str) -> ObjectClass:
    """A withdrawn class registered again: the same row, the new attributes, no samples."""
    cls.withdrawn_at, cls.attribute_key, cls.kind, cls.promoted_at = None, key, "novel", None
    session.flush()
    return cls


# ------------------------------------------------------------ model versions


def active_version_number(session: Session) -> int | None:
    """The cheap poll every API process runs: one indexed row."""
    return session.scalar(select(ModelVersion.version).where(ModelVersion.active))


def active_version(session: Session) -> ModelVersion | None:
    return session.scalar(select(ModelVersion).where(ModelVersion.active))


def get_version(session: Session, version: int) -> ModelVersion | None:
    return session.get(ModelVersion, version)


def list_versions(session: Session, after: int | None = None, limit: int | None = None,
                  summary: bool = False) -> list[ModelVersion]:
    """Versions, oldest first; with ``after``, those after it; at most ``limit``. With
    ``summary``, the class and sample lists (thousands of entries per version in a
    long-running fleet) stay unread and the database counts the classes."""
    stmt = select(ModelVersion).order_by(ModelVersion.version).limit(limit)
    if summary:
        stmt = stmt.options(
            defer(ModelVersion.classes), defer(ModelVersion.sample_ids),
            with_expression(ModelVersion.counted_classes, func.json_array_length(ModelVersion.classes)),
        )
    return list(session.scalars(stmt if after is None else stmt.where(ModelVersion.version > after)))


# Bundles are read in slices: a database driver converts a whole value while it holds the
# GIL, so reading a 3.3 MB bundle through psycopg2 held an API process's event loop (and
# every request in it) for up to 9 ms each time it loaded a new model version; in 256 kB
# slices, at most 3 ms.
BUNDLE_READ_BYTES = 256 * 1024


def bundle_data(session: Session, sha256: str) -> bytes | None:
    """The bytes of bundle ``sha256`` (None if there is none), checked against their hash."""
    size = session.scalar(select(Bundle.size).where(Bundle.sha256 == sha256))
    if size is None:
        return None
    parts = [
        session.scalar(
            select(func.substr(Bundle.data, start + 1, BUNDLE_READ_BYTES, type_=LargeBinary))
            .where(Bundle.sha256 == sha256)
        )
        for start in range(0, size, BUNDLE_READ_BYTES)
    ]
    data = b"".join(parts)  # LargeBinary gives bytes on every driver
    if len(data) != size or hashlib.sha256(data).hexdigest() != sha256:
        raise BundleError(f"stored bundle {sha256[:12]}… reads back as {len(data)} bytes of "
                          f"{size} with another hash: the store is damaged")
    return data


def store_bundle(session: Session, data: bytes, sha256: str | None = None) -> str:
    """Content-addressed: identical bundles (and bundle parts) are stored once. ``sha256``,
    when the caller has it already, must be the SHA-256 of ``data``."""
    sha = sha256 or hashlib.sha256(data).hexdigest()
    # only the key: session.get would read the whole stored bundle back
    if session.scalar(select(Bundle.sha256).where(Bundle.sha256 == sha)) is None:
        session.add(Bundle(sha256=sha, size=len(data), data=data))
        session.flush()
    return sha


def add_version(session: Session, **fields) -> ModelVersion:
    row = ModelVersion(active=False, **fields)
    session.add(row)
    session.flush()
    return row


def activate(session: Session, version: int) -> bool:
    """Make ``version`` the active one; False, and the caller must roll back, if there is
    no such version (pruned since it was read), as no version is active then."""
    # clear first: the partial unique index allows one active row at any instant
    session.execute(
        update(ModelVersion).where(ModelVersion.active, ModelVersion.version != version)
        .values(active=False)
    )
    done = session.execute(update(ModelVersion).where(ModelVersion.version == version).values(active=True))
    return done.rowcount == 1


# ---------------------------------------------------------------------- jobs


def add_job(
    session: Session, kind: str, class_id: int, sample_id: int | None = None,
    requested_by: str | None = None,
) -> Job:
    job = Job(kind=kind, status="queued", class_id=class_id, sample_id=sample_id,
              requested_by=requested_by)
    session.add(job)
    session.flush()
    return job


def get_job(session: Session, job_id: int) -> Job | None:
    return session.get(Job, job_id)


def list_jobs(
    session: Session, after: int | None = None, limit: int | None = None, *,
    status: str | None = None, kind: str | None = None, class_id: int | None = None,
) -> list[Job]:
    """Jobs by id, newest last; with ``after``, those after it; filtered by whatever is given."""
    stmt = select(Job).order_by(Job.id).limit(limit)
    if after is not None:
        stmt = stmt.where(Job.id > after)
    for column, value in ((Job.status, status), (Job.kind, kind), (Job.class_id, class_id)):
        if value is not None:
            stmt = stmt.where(column == value)
    return list(session.scalars(stmt))


def claim_queued_jobs(session: Session, worker_id: str) -> list[Job]:
    """Mark every queued job running for this worker and commit; returns them.

    FOR UPDATE SKIP LOCKED lets PostgreSQL workers claim side by side (SQLite
    ignores it and serialises writers); the status guard in the UPDATE makes a
    lost race harmless on either.
    """
    stmt = (
        select(Job.id).where(Job.status == "queued").order_by(Job.id)
        .with_for_update(skip_locked=True)
    )
    ids = list(session.scalars(stmt))
    if not ids:
        session.rollback()
        return []
    now = utcnow()
    session.execute(
        update(Job).where(Job.id.in_(ids), Job.status == "queued")
        .values(status="running", claimed_by=worker_id, started_at=now, heartbeat_at=now)
    )
    session.commit()
    mine = select(Job).where(Job.id.in_(ids), Job.claimed_by == worker_id, Job.status == "running")
    return list(session.scalars(mine.order_by(Job.id)))


def requeue_running(session: Session) -> int:
    """Jobs left ``running`` by a worker that died go back to the queue."""
    res = session.execute(
        update(Job).where(Job.status == "running")
        .values(status="queued", claimed_by=None, started_at=None, heartbeat_at=None)
    )
    return res.rowcount or 0


def finish_jobs(
    session: Session, job_ids: Sequence[int], status: str, version: int | None = None,
    error: str | None = None,
) -> None:
    session.execute(
        update(Job).where(Job.id.in_(job_ids))
        .values(status=status, model_version=version, error=error, finished_at=utcnow())
    )


def registration_failed(session: Session, class_id: int) -> bool:
    """Whether the class's latest registration job failed (so it may be registered again)."""
    status = session.scalar(
        select(Job.status).where(Job.class_id == class_id, Job.kind == "register_class")
        .order_by(Job.id.desc()).limit(1)
    )
    return status == "failed"


def jobs_finished_since(session: Session, since) -> list[tuple]:
    stmt = (
        select(Job.id, Job.status, Job.created_at, Job.started_at, Job.finished_at)
        .where(Job.finished_at >= since).order_by(Job.finished_at)
    )
    return [tuple(row) for row in session.execute(stmt)]


FINISHED_JOB_STATUSES = ("succeeded", "failed")


def finished_job_ids(session: Session, ids: Sequence[int]) -> list[int]:
    """Those of ``ids`` whose jobs have succeeded or failed."""
    return list(session.scalars(select(Job.id).where(Job.id.in_(ids), Job.status.in_(FINISHED_JOB_STATUSES))))


def jobs_by_status(session: Session) -> dict[str, int]:
    return dict(session.execute(select(Job.status, func.count()).group_by(Job.status)).all())


def stored_model_figures(session: Session) -> tuple[int, int]:
    """(model versions, bytes of bundle rows) the store holds: what retention bounds."""
    versions = session.scalar(select(func.count()).select_from(ModelVersion))
    size = session.scalar(select(func.coalesce(func.sum(Bundle.size), 0)))
    return int(versions), int(size)


# ------------------------------------------------------------------ API keys

SCOPES = ("read", "enroll", "admin")  # each includes the rights of those before it
KEY_PREFIX = "tzk_"


def hash_key(key: str) -> str:
    """Keys are 256-bit random strings, so a plain SHA-256 is a safe way to store them."""
    return hashlib.sha256(key.encode()).hexdigest()


def create_api_key(session: Session, scope: str, name: str | None = None) -> tuple[str, ApiKey]:
    """A new key (returned once, never stored) and its row."""
    if scope not in SCOPES:
        raise ValueError(f"scope must be one of {', '.join(SCOPES)}, not '{scope}'")
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    row = ApiKey(key_sha256=hash_key(key), prefix=key[:12], scope=scope, name=name)
    session.add(row)
    session.flush()
    return key, row


def list_api_keys(session: Session) -> list[ApiKey]:
    return list(session.scalars(select(ApiKey).order_by(ApiKey.id)))


def revoke_api_key(session: Session, key_id: int) -> bool:
    res = session.execute(
        update(ApiKey).where(ApiKey.id == key_id, ApiKey.revoked_at.is_(None))
        .values(revoked_at=utcnow())
    )
    return (res.rowcount or 0) == 1


def api_key_table(session: Session) -> tuple[bool, dict[str, tuple[int, str]]]:
    """(whether any key was ever created, {sha256: (id, scope)} of the usable ones)."""
    rows = session.execute(select(ApiKey.id, ApiKey.key_sha256, ApiKey.scope, ApiKey.revoked_at))
    any_key, usable = False, {}
    for key_id, sha, scope, revoked in rows:
        any_key = True
        if revoked is None:
            usable[sha] = (key_id, scope)
    return any_key, usable


# ------------------------------------------------------------- idempotency


def get_idempotency(session: Session, principal: str, key: str) -> IdempotencyRecord | None:
    return session.get(IdempotencyRecord, (principal, key))


def add_idempotency(
    session: Session, principal: str, key: str, fingerprint: str, status_code: int, body: dict,
    location: str | None,
) -> None:
    """Flushed at once: a concurrent request with the same key fails here (IntegrityError)."""
    session.add(IdempotencyRecord(
        principal=principal, key=key, fingerprint=fingerprint, status_code=status_code,
        body=body, location=location,
    ))
    session.flush()


def purge_idempotency(session: Session, before: datetime) -> int:
    res = session.execute(delete(IdempotencyRecord).where(IdempotencyRecord.created_at < before))
    return res.rowcount or 0


def jsonable(obj):
    """Metrics as strict JSON: numpy scalars to Python, NaN and infinities to None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
