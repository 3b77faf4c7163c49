import logging

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST
from sqlalchemy.exc import SQLAlchemyError

from app.api import problems
from app.api.deps import HolderDep, MetricsDep, SessionDep
from app.api.problems import Problem
from app.api.schemas import Health
from app.store.db import ping

log = logging.getLogger(__name__)

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
async def healthz(holder: HolderDep) -> Health:
    """The process is alive; the model version it serves, once one is loaded."""
    model = holder.current
    return Health(status="ok", model_version=None if model is None else model.version)


@router.get("/readyz", response_model=Health, responses=problems.responses(503))
def readyz(session: SessionDep, holder: HolderDep) -> Health:
    """The store answers and a model is loaded."""
    try:
        ping(session)
    except SQLAlchemyError:
        raise Problem(503, "the store is not reachable", "database") from None
    model = holder.current
    if model is None:
        raise Problem(503, "no model is loaded yet", "model", {"Retry-After": "5"})
    return Health(status="ready", model_version=model.version)


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"}
    },
)
def metrics(request: Request, session: SessionDep, metrics: MetricsDep) -> Response:
    """Prometheus metrics: requests, latencies, recognitions, enrollments, jobs, model version
    (of every process when `serve` runs several)."""
    if request.app.state.service.job_metrics_at_scrape:  # else one process reads them on a timer
        try:
            metrics.read_store(session)
        except SQLAlchemyError:  # the process's own metrics are still worth a scrape
            log.warning("metrics: the store is not reachable; job figures left as they were")
    body, content_type = metrics.exposition()
    return Response(body, media_type=content_type)
