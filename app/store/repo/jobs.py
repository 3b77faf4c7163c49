"""Jobs: the enrolments, withdrawals and new descriptions queued for the worker, and
how they are claimed, finished and reported."""

from __future__ import annotations

from collections.abc import Collection, Sequence

from sqlalchemy import Row, exists, func, or_, select, update
from sqlalchemy.orm import Session

from app.store.enums import JobKind, JobStatus
from app.store.models import Job, Sample, utcnow


def add_job(
    session: Session,
    kind: str,
    class_id: int | None,
    sample_id: int | None = None,
    requested_by: str | None = None,
    attribute_id: int | None = None,
    warnings: list[str] | None = None,
) -> Job:
    job = Job(
        kind=kind,
        status=JobStatus.QUEUED,
        class_id=class_id,
        sample_id=sample_id,
        attribute_id=attribute_id,
        requested_by=requested_by,
        warnings=warnings or None,
    )
    session.add(job)
    session.flush()
    return job


def get_job(session: Session, job_id: int) -> Job | None:
    return session.get(Job, job_id)


def get_jobs(session: Session, job_ids: Collection[int]) -> list[Job]:
    """The jobs ``job_ids``, by id."""
    return list(session.scalars(select(Job).where(Job.id.in_(job_ids)).order_by(Job.id)))


def list_jobs(
    session: Session,
    after: int | None = None,
    limit: int | None = None,
    *,
    status: str | None = None,
    kind: str | None = None,
    class_id: int | None = None,
) -> list[Job]:
    """Jobs by id, newest last; with ``after``, those after it; filtered by whatever is given."""
    stmt = select(Job).order_by(Job.id).limit(limit)
    if after is not None:
        stmt = stmt.where(Job.id > after)
    for column, value in ((Job.status, status), (Job.kind, kind), (Job.class_id, class_id)):
        if value is not None:
            stmt = stmt.where(column == value)
    return list(session.scalars(stmt))


def jobs_pending(session: Session) -> bool:
    """Whether any job is queued, or running (perhaps left so by a worker that died)."""
    active = (JobStatus.QUEUED, JobStatus.RUNNING)
    return bool(session.scalar(select(exists().where(Job.status.in_(active)))))


def claim_queued_jobs(session: Session, worker_id: str) -> list[Job]:
    """Mark every queued job running for this worker and commit; returns them.

    FOR UPDATE SKIP LOCKED lets PostgreSQL workers claim side by side (SQLite
    ignores it and serialises writers); the status guard in the UPDATE makes a
    lost race harmless on either.
    """
    stmt = (
        select(Job.id)
        .where(Job.status == JobStatus.QUEUED)
        .order_by(Job.id)
        .with_for_update(skip_locked=True)
    )
    ids = list(session.scalars(stmt))
    if not ids:
        session.rollback()
        return []
    now = utcnow()
    session.execute(
        update(Job)
        .where(Job.id.in_(ids), Job.status == JobStatus.QUEUED)
        .values(status=JobStatus.RUNNING, claimed_by=worker_id, started_at=now)
    )
    session.commit()
    mine = select(Job).where(
        Job.id.in_(ids), Job.claimed_by == worker_id, Job.status == JobStatus.RUNNING
    )
    return list(session.scalars(mine.order_by(Job.id)))


def requeue_running(session: Session) -> int:
    """Jobs left ``running`` by a worker that died go back to the queue."""
    res = session.execute(
        update(Job)
        .where(Job.status == JobStatus.RUNNING)
        .values(status=JobStatus.QUEUED, claimed_by=None, started_at=None)
    )
    return res.rowcount or 0


def finish_jobs(
    session: Session,
    job_ids: Sequence[int],
    status: str,
    version: int | None = None,
    error: str | None = None,
) -> None:
    session.execute(
        update(Job)
        .where(Job.id.in_(job_ids))
        .values(status=status, model_version=version, error=error, finished_at=utcnow())
    )


def registration_failed(session: Session, class_id: int) -> bool:
    """Whether the class's latest registration job failed (so it may be registered again)."""
    status = session.scalar(
        select(Job.status)
        .where(Job.class_id == class_id, Job.kind == JobKind.REGISTER_CLASS)
        .order_by(Job.id.desc())
        .limit(1)
    )
    return status == JobStatus.FAILED


def latest_registrations(session: Session) -> list[Row]:
    """Rows of ``id, class_id, status`` of each class's latest registration job (a withdrawn
    class registered again has several)."""
    latest = (
        select(func.max(Job.id))
        .where(Job.kind == JobKind.REGISTER_CLASS)
        .group_by(Job.class_id)
        .scalar_subquery()
    )
    return list(session.execute(select(Job.id, Job.class_id, Job.status).where(Job.id.in_(latest))))


def sample_enrolments(session: Session, claimed: Collection[int]) -> list[Row]:
    """Rows of ``job_id, class_id, sample_id, withdrawn_at`` (the sample's) of every job that
    added a sample and succeeded, or is one of the jobs ``claimed``."""
    stmt = (
        select(
            Job.id.label("job_id"), Job.class_id, Sample.id.label("sample_id"), Sample.withdrawn_at
        )
        .join(Sample, Sample.id == Job.sample_id)
        .where(
            Job.kind == JobKind.ADD_SAMPLE,
            or_(Job.status == JobStatus.SUCCEEDED, Job.id.in_(claimed)),
        )
    )
    return list(session.execute(stmt))


def jobs_finished_since(session: Session, since) -> list[tuple]:
    stmt = (
        select(Job.id, Job.status, Job.created_at, Job.started_at, Job.finished_at)
        .where(Job.finished_at >= since)
        .order_by(Job.finished_at)
    )
    return [tuple(row) for row in session.execute(stmt)]


FINISHED_JOB_STATUSES = (JobStatus.SUCCEEDED, JobStatus.FAILED)


def finished_job_ids(session: Session, ids: Sequence[int]) -> list[int]:
    """Those of ``ids`` whose jobs have succeeded or failed."""
    stmt = select(Job.id).where(Job.id.in_(ids), Job.status.in_(FINISHED_JOB_STATUSES))
    return list(session.scalars(stmt))


def jobs_by_status(session: Session) -> dict[str, int]:
    return dict(session.execute(select(Job.status, func.count()).group_by(Job.status)).all())
