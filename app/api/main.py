"""The FastAPI application: ``create_app(settings)`` wires store, model, worker and routes."""

from __future__ import annotations

import gc
import logging
import time
from collections.abc import AsyncIterator
from contextlib import ExitStack, asynccontextmanager
from importlib.resources import files

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from starlette.datastructures import Headers
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api import openapi, problems
from app.api.deps import Replay, replay_handler
from app.api.fast_path import RecognizeFastPath
from app.api.routes import attributes, classes, describe, health, jobs, models, recognize, samples
from app.api.state import ServiceState
from app.api.warm import warm_words
from app.config import Settings
from app.service.bootstrap import Trainer, ensure_ready
from app.service.holder import ModelHolder
from app.service.input_monitor import InputDriftPoller
from app.service.job_watch import JobWatch
from app.service.keys import KeyRing, RateLimiter
from app.service.metrics import JobMetricsPoller, Metrics
from app.service.recognition import RecognitionService
from app.store.bundles import ExportCache
from app.store.db import make_engine, make_sessionmaker
from app.store.in_use import opened_by_service

log = logging.getLogger(__name__)

DESCRIPTION = """Recognise objects from tactile samples: objects the model was trained on,
and novel objects an operator registered by their attributes (zero-shot), refined by
real samples (one-shot). Every error is an RFC 9457 `application/problem+json` body."""


def create_app(
    settings: Settings | None = None,
    trainer: Trainer | None = None,
    process_index: int | None = None,
) -> FastAPI:
    """``trainer`` replaces the bootstrap training (tests hand in a trained model);
    ``process_index`` is this process's number when ``serve`` runs several (process 0
    then reads the job figures for ``/metrics`` for all of them)."""
    settings = settings or Settings()
    engine = make_engine(settings.sqlalchemy_url, settings.db_timeout_seconds)
    sessions = make_sessionmaker(engine)
    metrics = Metrics()
    holder = ModelHolder(sessions, settings.model_poll_seconds, metrics)
    keys = KeyRing(sessions, settings.api_keys, settings.api_key_refresh_seconds)
    job_metrics = JobMetricsPoller(metrics, sessions) if process_index == 0 else None
    recognition = RecognitionService(
        metrics,
        settings.top_k,
        settings.batch_limit,
        input_window=settings.input_window,
        known_kept=settings.known_kept,
        outliers=settings.outliers,
    )
    # any process may answer a scrape: each computes its input gauges on a timer
    input_drift = InputDriftPoller(recognition.inputs) if process_index is not None else None
    job_watch = JobWatch(sessions)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        # held from before the migration to after the last query: no restore under our feet
        with ExitStack() as held:
            await run_in_threadpool(held.enter_context, opened_by_service(settings.sqlalchemy_url))
            async with serving():
                yield

    @asynccontextmanager
    async def serving() -> AsyncIterator[None]:
        await run_in_threadpool(ensure_ready, settings, engine, sessions, trainer)
        await run_in_threadpool(holder.refresh)
        await run_in_threadpool(keys.refresh)
        # Everything imported and loaded so far (torch, pydantic, the model) lives as long
        # as the process; scanning it made each full collection under load take ~165 ms,
        # which was the p99 recognition latency. Frozen, the collector skips it.
        gc.collect()
        gc.freeze()
        holder.start()
        keys.start()
        if job_metrics is not None:
            job_metrics.start()
        if input_drift is not None:
            input_drift.start()
        embedded = None
        if settings.embedded_worker:
            from worker import Worker, start_in_thread

            # the worker hands each model it builds to this process's holder: no reload
            worker = Worker(
                settings,
                sessions,
                on_activate=holder.serve,
                parts=holder.parts,
                handover=holder.handing_over,
            )
            embedded = start_in_thread(worker)
        if settings.warm_words:  # ready now: the first description need not load the model
            await run_in_threadpool(warm_words, sessions)
        try:
            yield
        finally:
            if embedded is not None:
                thread, stop = embedded
                stop.set()
                thread.join(timeout=30)
            await job_watch.close()
            if job_metrics is not None:
                job_metrics.stop()
            if input_drift is not None:
                input_drift.stop()
            keys.stop()
            holder.stop()
            engine.dispose()

    app = FastAPI(
        title="Tactile recognition service",
        version="1",
        description=DESCRIPTION,
        lifespan=lifespan,
        telemetry=None
        if settings.opentelemetry
        else {"tracing": False, "metrics": False, "logs": False},
        docs_url=None,  # served below from the package: no CDN
        redoc_url=None,
        generate_unique_id_function=operation_id,
    )
    app.state.service = ServiceState(
        settings=settings,
        sessions=sessions,
        local_store=engine.dialect.name == "sqlite",
        holder=holder,
        metrics=metrics,
        job_metrics_at_scrape=process_index is None,
        recognition=recognition,
        keys=keys,
        job_watch=job_watch,
        exports=ExportCache(),
        limiter=RateLimiter(settings.rate_limit, settings.rate_burst),
    )
    problems.install(app)
    app.add_exception_handler(Replay, replay_handler)
    # recognize first: routes are matched in order, and it is the hot path (robots call it
    # hundreds of times a second; matching each earlier route cost ~20 µs per request)
    for module in (recognize, health, describe, attributes, classes, samples, jobs, models):
        app.include_router(module.router)
    _mount_docs(app)
    openapi.install(app)
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    if settings.cors_origins:  # closed by default: no CORS headers at all
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "PATCH", "DELETE"],
            allow_headers=["Content-Type", "X-API-Key", "Idempotency-Key"],
        )
    app.add_middleware(RequestMetrics, metrics=metrics)
    if not settings.opentelemetry:  # its spans name the route FastAPI's router selected
        # the outermost: it builds the route's own app from the middleware above
        app.add_middleware(RecognizeFastPath)
    return app


def operation_id(route: APIRoute) -> str:
    """``classes-register_class`` rather than ``register_class_v1_classes_post``: what client
    generators turn into method names (the FastAPI full-stack template's convention)."""
    return f"{route.tags[0]}-{route.name}" if route.tags else route.name  # the docs page has none


def _mount_docs(app: FastAPI) -> None:
    # Swagger UI 5 from the fastapi-swagger package: it reads OpenAPI 3.1, which FastAPI writes
    app.mount(
        "/static/swagger-ui",
        StaticFiles(directory=str(files("fastapi_swagger") / "resources")),
        name="swagger-ui",
    )

    @app.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url,
            title=f"{app.title} – API docs",
            swagger_js_url="/static/swagger-ui/swagger-ui-bundle.js",
            swagger_css_url="/static/swagger-ui/swagger-ui.css",
            swagger_favicon_url="/static/swagger-ui/favicon-32x32.png",
        )


class BodySizeLimit:
    """413 as problem+json for bodies over the cap. (FastAPI's own ``max_body_size``
    answers text/plain, which would break the every-error-is-a-problem rule.)"""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    def _too_large(self) -> problems.Problem:
        return problems.body_too_large(self.max_bytes)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = Headers(scope=scope).get("content-length", "")
        if declared.isdigit():
            if int(declared) > self.max_bytes:
                request = Request(scope)
                exc = self._too_large()
                response = problems.problem_response(request, 413, exc.detail, exc.errors)
                await response(scope, receive, send)
                return
            # the server reads no more than the declared length: nothing to count
            await self.app(scope, receive, send)
            return
        seen = 0

        async def counted() -> Message:  # bodies sent without a length are counted as they come
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.max_bytes:
                raise self._too_large()
            return message

        await self.app(scope, counted, send)


class RequestMetrics:
    """Counts and times every request by route template (pure ASGI: cheap on the hot path)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("route")
            path = getattr(route, "path", None) or "unmatched"
            self.metrics.observe_request(scope["method"], path, status, time.perf_counter() - start)
