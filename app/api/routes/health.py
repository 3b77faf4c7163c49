import logging

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError

from app.api import problems
from app.api.deps import HolderDep, MetricsDep, SessionDep
from app.api.problems import Problem
from app.api.schemas import Health
from app.store import repo

log = logging.getLogger(__name__)

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
async def healthz() -> Health:
    """The process is alive."""
    return Health(status="ok")


@router.get("/readyz", response_model=Health, responses=problems.responses(503))
def readyz(session: SessionDep, holder: HolderDep) -> Health:
    """The store answers and a model is loaded."""
    try:
        session.execute(text("SELECT 1"))
    except SQLAlchemyError:
        raise Problem(503, "the store is not reachable", "database") from None
    model = holder.current
    if model is None:
        raise Problem(503, "no model is loaded yet", "model", {"Retry-After": "5"})
    return Health(status="ready", model_version=model.version)


@router.get(
    "/metrics", response_class=Response,
    responses={200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"}},
)
def metrics(session: SessionDep, metrics: MetricsDep) -> Response:
    """Prometheus metrics: requests, latencies, recognitions, enrollments, jobs, model version."""
    try:
        counts = repo.jobs_by_status(session)
        for status in ("queued", "running", "succeeded", "failed"):
            metrics.jobs.labels(status).set(counts.get(status, 0))
        metrics.observe_finished_jobs(repo.jobs_finished_since(session, metrics.jobs_seen_since))
    except SQLAlchemyError:  # the process's own metrics are still worth a scrape
        log.warning("metrics: the store is not reachable; job figures left as they were")
    return Response(generate_latest(metrics.registry), media_type=CONTENT_TYPE_LATEST)
