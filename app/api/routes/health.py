import logging

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST
from pydantic import Field
from sqlalchemy.exc import SQLAlchemyError

from app.api import problems
from app.api.deps import HolderDep, MetricsDep, SessionDep, SettingsDep
from app.api.problems import Problem
from app.api.schemas import Health
from app.service.bootstrap import first_model_missing, starts_empty
from app.store.db import ping

log = logging.getLogger(__name__)

router = APIRouter(tags=["health"])


class Liveness(Health):
    batch_limit: int = Field(
        description="Most samples or trials one `POST /v1/recognize` or `POST /v1/describe` "
        "takes (`TACTILE_BATCH_LIMIT`): a client splits larger batches."
    )


@router.get("/healthz", response_model=Liveness)
async def healthz(request: Request, holder: HolderDep) -> Liveness:
    """The process is alive; the model version it serves, once one is loaded, and its
    batch limit."""
    model = holder.current
    return Liveness(
        status="ok",
        model_version=None if model is None else model.version,
        batch_limit=request.app.state.service.recognition.batch_limit,
    )


class Readiness(Health):
    detail: str | None = Field(
        None,
        description="Set when the process serves another version than the active one, and "
        "why: the active version's stored bundle is damaged (`tactile-zsl store check` "
        "names it), so it serves the newest intact one; or, for a service started without a "
        "dataset, what its first model waits for.",
    )


@router.get(
    "/readyz",
    response_model=Readiness,
    response_model_exclude_none=True,  # detail only when there is something to say
    responses=problems.responses(503),
)
def readyz(session: SessionDep, holder: HolderDep, settings: SettingsDep) -> Readiness:
    """The store answers and a model is loaded (503 with `Retry-After` otherwise). A service
    started without a dataset is ready before its first model: it takes attributes and
    classes then (`detail` says what the first model waits for)."""
    try:
        ping(session)
    except SQLAlchemyError as exc:
        log.warning("readyz: the store is not reachable: %s", getattr(exc, "orig", exc))
        raise Problem(503, "the store is not reachable", "database", {"Retry-After": "1"}) from None
    model = holder.current
    if model is None and starts_empty(settings):
        missing = first_model_missing(session) or "the first model is being trained"
        return Readiness(status="ready", model_version=None, detail=missing)
    if model is None:
        raise Problem(503, "no model is loaded yet", "model", {"Retry-After": "5"})
    return Readiness(status="ready", model_version=model.version, detail=holder.degraded)


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"}
    },
)
def metrics(request: Request, session: SessionDep, metrics: MetricsDep) -> Response:
    """Prometheus metrics: requests, latencies, recognitions, enrollments, jobs, model version
    (of every process when `serve` runs several), and the health of recent inputs: the
    outlier rate and each channel's drift against the training data (docs/DEPLOY.md)."""
    if request.app.state.service.job_metrics_at_scrape:  # else one process reads them on a timer
        try:
            metrics.read_store(session)
        except SQLAlchemyError:  # the process's own metrics are still worth a scrape
            log.warning("metrics: the store is not reachable; job figures left as they were")
    request.app.state.service.recognition.inputs.refresh()  # this process's input window
    body, content_type = metrics.exposition()
    return Response(body, media_type=content_type)
