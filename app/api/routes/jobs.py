import time
from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.concurrency import run_in_threadpool
from sqlalchemy.orm import Session

from app.api import problems
from app.api.deps import (
    MAX_ROW_ID,
    HolderDep,
    JobWatchDep,
    PageDep,
    ReadAccess,
    RowId,
    SessionDep,
    SettingsDep,
)
from app.api.problems import Problem, not_found
from app.api.schemas import JobList, JobOut
from app.service.holder import ModelWaitTimeout
from app.store import repo
from app.store.enums import JobKind, JobStatus
from app.store.models import Job

router = APIRouter(
    prefix="/v1/jobs",
    tags=["jobs"],
    dependencies=[ReadAccess],
    responses=problems.responses(401, 403, 404, 422, 429),
)

MAX_WAIT_SECONDS = 20  # how long a request may hold its event (a shutdown answers it at once)

WaitSeconds = Annotated[
    float,
    Query(
        ge=0,
        le=MAX_WAIT_SECONDS,
        description="Seconds to wait for the job to finish before answering (long polling): the "
        "answer comes as soon as it has succeeded or failed, or after this long (or when the API "
        "process shuts down) with its status then. One waiting request replaces many polls.",
    ),
]


def _read_job(session: Session, job_id: int) -> Job | None:
    job = repo.get_job(session, job_id)
    session.close()  # give the connection back: a waiting request must not hold one
    return job


@router.get("", response_model=JobList)
def list_jobs(
    session: SessionDep,
    page: PageDep,
    status: Annotated[JobStatus | None, Query(description="Only jobs in this status.")] = None,
    kind: Annotated[JobKind | None, Query(description="Only jobs of this kind.")] = None,
    class_id: Annotated[
        int | None, Query(ge=1, le=MAX_ROW_ID, description="Only jobs of this class.")
    ] = None,
) -> JobList:
    """Jobs by id, a page at a time, e.g. ``?status=failed`` for the enrolments that did not
    make it and why, or ``?class_id=`` for one class's history."""
    rows = repo.list_jobs(
        session, page.after, page.limit + 1, status=status, kind=kind, class_id=class_id
    )
    rows, next_after = page.cut(rows, lambda j: j.id)
    return JobList(jobs=[JobOut.model_validate(j) for j in rows], next_after=next_after)


@router.get("/{job_id}", response_model=JobOut, responses=problems.responses(503))
async def get_job(
    job_id: RowId,
    session: SessionDep,
    holder: HolderDep,
    watch: JobWatchDep,
    settings: SettingsDep,
    wait: WaitSeconds = 0,
) -> JobOut:
    """An enrollment's progress: queued, running, succeeded (with the model version
    that includes it) or failed (with the error). A succeeded job's version is served by
    this process before the answer: a 503 with `Retry-After` when it has not loaded it
    within `TACTILE_MODEL_WAIT_SECONDS`."""
    deadline = time.monotonic() + wait
    job = await run_in_threadpool(_read_job, session, job_id)
    if job is None:
        raise not_found("job", "job_id", job_id)
    if job.status not in repo.FINISHED_JOB_STATUSES and wait > 0:
        if await watch.wait(job_id, max(0.0, deadline - time.monotonic())):
            job = await run_in_threadpool(_read_job, session, job_id)
    served = holder.current
    if job.model_version is not None and (served is None or served.version < job.model_version):
        # whoever sees "succeeded" here gets the new model from this process next
        try:
            await holder.at_least(job.model_version, settings.model_wait_seconds)
        except ModelWaitTimeout as exc:
            detail = f"job {job_id} succeeded: {exc}"
            raise Problem(503, detail, "job_id", {"Retry-After": "5"}) from None
    return JobOut.model_validate(job)
