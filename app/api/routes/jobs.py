from fastapi import APIRouter

from app.api import problems
from app.api.deps import HolderDep, ReadAccess, RowId, SessionDep
from app.api.problems import not_found
from app.api.schemas import JobOut
from app.store import repo

router = APIRouter(
    prefix="/v1/jobs", tags=["jobs"], dependencies=[ReadAccess],
    responses=problems.responses(401, 403, 404, 422, 429),
)


@router.get("/{job_id}", response_model=JobOut)
def get_job(job_id: RowId, session: SessionDep, holder: HolderDep) -> JobOut:
    """An enrollment's progress: queued, running, succeeded (with the model version
    that includes it) or failed (with the error)."""
    job = repo.get_job(session, job_id)
    if job is None:
        raise not_found("job", "job_id", job_id)
    served = holder.current
    if job.model_version is not None and served is not None and served.version < job.model_version:
        # whoever sees "succeeded" here gets the new model from this process next
        holder.refresh()
    return JobOut.model_validate(job)
