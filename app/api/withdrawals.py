"""The 202 of both withdrawal routes (``app.service.enrolment`` marks the class or sample
and queues the job that takes it out of the served model)."""

from __future__ import annotations

from fastapi import Response
from sqlalchemy.orm import Session

from app.api.deps import Idempotency
from app.api.schemas import JobOut, Withdrawal
from app.store.models import Job


def withdrawal(
    session: Session,
    idempotency: Idempotency,
    response: Response,
    class_id: int,
    sample_id: int | None,
    job: Job,
) -> Withdrawal:
    """The withdrawal's answer, committed with its change and job (kept for retries)."""
    out = Withdrawal(class_id=class_id, sample_id=sample_id, job=JobOut.model_validate(job))
    idempotency.accept(session, out, job.id, response)
    return out
