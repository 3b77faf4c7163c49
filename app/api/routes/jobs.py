import asyncio
import logging
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
from app.api.problems import not_found
from app.api.schemas import JobList, JobOut
from app.service.holder import ModelHolder
from app.store import repo
from app.store.enums import JobKind, JobStatus
from app.store.models import Job

log = logging.getLogger(__name__)

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


@router.get("/{job_id}", response_model=JobOut)
async def get_job(
    job_id: RowId,
    session: SessionDep,
    holder: HolderDep,
    watch: JobWatchDep,
    settings: SettingsDep,
    wait: WaitSeconds = 0,
) -> JobOut:
    """An enrollment's progress: queued, running, succeeded (with the model version
    that includes it) or failed (with the error). The answer comes as soon as the job has
    finished, without waiting for this process to load that version (seconds for a large
    model): it starts loading it then. To be answered by that version, pass it to
    `POST /v1/recognize` as `min_model_version`."""
    deadline = time.monotonic() + wait
    job = await run_in_threadpool(_read_job, session, job_id)
    if job is None:
        raise not_found("job", "job_id", job_id)
    if job.status not in repo.FINISHED_JOB_STATUSES and wait > 0:
        if await watch.wait(job_id, max(0.0, deadline - time.monotonic())):
            job = await run_in_threadpool(_read_job, session, job_id)
    served = holder.current
    if job.model_version is not None and (served is None or served.version < job.model_version):
        # this process loads the version now rather than at its next poll; the answer does
        # not wait for it (a robot's next recognition names it: min_model_version)
        _catch_up(holder, job.model_version, settings.model_wait_seconds)
    return JobOut.model_validate(job)


_catching_up: set[asyncio.Task] = set()  # the loads begun, held until done (asyncio's advice)


def _catch_up(holder: ModelHolder, version: int, wait_seconds: float) -> None:
    """Start this process's load of ``version`` (shared with every request that waits for
    it) without waiting for it."""
    task = asyncio.create_task(holder.at_least(version, wait_seconds))
    _catching_up.add(task)
    task.add_done_callback(_caught_up)


def _caught_up(task: asyncio.Task) -> None:
    _catching_up.discard(task)
    if not task.cancelled() and (exc := task.exception()) is not None:
        # slow (the load goes on) or damaged (the holder serves the newest intact one)
        log.info("loading the version a job made: %s", exc)
