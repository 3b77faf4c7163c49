"""What both withdrawal routes do once the class or sample is marked: queue the job that
takes it out of the served model, in the same transaction."""

from __future__ import annotations

from fastapi import Response
from sqlalchemy.orm import Session

from app.api.deps import Idempotency
from app.api.schemas import JobOut, Withdrawal
from app.service.keys import Principal
from app.service.metrics import Metrics
from app.store import repo
from app.store.enums import JobKind


def queue_withdrawal(
    session: Session,
    idempotency: Idempotency,
    metrics: Metrics,
    response: Response,
    principal: Principal,
    class_id: int,
    sample_id: int | None,
) -> Withdrawal:
    """Queue the withdrawal's job and commit it with the change; the 202's body."""
    kind = JobKind.WITHDRAW_CLASS if sample_id is None else JobKind.WITHDRAW_SAMPLE
    with idempotency.writing(session):  # a concurrent retry with this key may win
        job = repo.add_job(session, kind, class_id, sample_id, requested_by=principal.id)
        out = Withdrawal(class_id=class_id, sample_id=sample_id, job=JobOut.model_validate(job))
        idempotency.accept(session, out, job.id, response)
    metrics.withdrawals.labels("class" if sample_id is None else "sample").inc()
    return out
