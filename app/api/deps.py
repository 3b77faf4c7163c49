"""Dependencies: settings, a database session per request, the served model, the API key."""

from __future__ import annotations

import functools
import hashlib
import hmac
import json
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import contextmanager
from typing import Annotated, NamedTuple

from fastapi import Depends, Header, Path, Query, Request, Response, Security
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from fastapi.security import APIKeyHeader
from pydantic import BaseModel
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.api.problems import Problem
from app.api.state import ServiceState
from app.config import Settings
from app.service.bootstrap import first_model_missing, starts_empty
from app.service.holder import LoadedModel, ModelHolder
from app.service.job_watch import JobWatch
from app.service.keys import Principal, retry_after
from app.service.metrics import Metrics
from app.service.recognition import RecognitionService
from app.store import repo
from app.store.bundles import ExportCache
from app.words.interpret import TextInterpreter

# async: trivial dependencies then run on the event loop, not in the thread pool


def service(request: Request) -> ServiceState:
    return request.app.state.service


async def get_settings(request: Request) -> Settings:
    return service(request).settings


async def get_holder(request: Request) -> ModelHolder:
    return service(request).holder


async def get_job_watch(request: Request) -> JobWatch:
    return service(request).job_watch


async def get_metrics(request: Request) -> Metrics:
    return service(request).metrics


async def get_exports(request: Request) -> ExportCache:
    return service(request).exports


async def get_session(request: Request) -> AsyncIterator[Session]:
    """The request's session, opened and closed on the event loop: a sync dependency would cost two
    more worker-thread hops (0.2–0.5 ms of CPU each, bench/thread_hops.py) around the route's own.
    Opening does no I/O (the route's first query checks out a connection in its thread); closing
    gives the connection back with a rollback, instant on SQLite and a network round trip elsewhere,
    which then goes to a worker thread."""
    session = service(request).sessions()
    try:
        yield session
    finally:
        if session.in_transaction() and not service(request).local_store:
            await run_in_threadpool(session.close)
        else:
            session.close()


async def current_model(request: Request) -> LoadedModel:
    """The snapshot a request works with from start to end, even if a swap happens."""
    model = service(request).holder.current
    if model is None:
        raise await _no_model(service(request))
    return model


async def _no_model(state: ServiceState) -> Problem:
    """409 saying what is missing for a service started empty, else 503 (loading). The
    store query of a service started empty runs in the thread pool, off the event loop."""
    if starts_empty(state.settings):
        return await run_in_threadpool(_what_is_missing, state)
    return _loading()


def _loading() -> Problem:
    return Problem(503, "no model is loaded yet; try again shortly", "model", {"Retry-After": "5"})


def _what_is_missing(state: ServiceState) -> Problem:
    with state.sessions() as s:
        missing = first_model_missing(s)
    return Problem(409, missing, "model") if missing else _loading()


async def get_model(request: Request) -> LoadedModel:
    return await current_model(request)


async def get_optional_model(request: Request) -> LoadedModel | None:
    """The served model, or None before a service started empty has its first one."""
    return service(request).holder.current


api_key_header = APIKeyHeader(
    name="X-API-Key",
    auto_error=False,
    description="Needed on every /v1 request once any API key exists.",
)


def header(request: Request, name: bytes) -> str | None:
    """``request.headers.get(name)`` for a lower-case ``name`` (the first such header),
    without building the request's ``Headers``: what the recognize path reads."""
    for key, value in request.scope["headers"]:
        if key == name:
            return value.decode("latin-1")
    return None


def authorize(
    request: Request, key: str | None, scope: str, state: ServiceState | None = None
) -> Principal:
    """The caller of ``request``: 401 without a valid key (once keys exist), 403 without
    ``scope``, 429 over the rate. ``state``: the app's, when the caller has it."""
    state = state or service(request)
    if not state.keys.required:
        client = request.scope.get("client")  # request.client, without its Address
        principal = Principal(f"addr:{client[0] if client else 'unknown'}", "admin")
    else:
        principal = state.keys.authenticate(key) if key else None
        if principal is None:
            raise Problem(
                401,
                "a valid X-API-Key header is required",
                "X-API-Key",
                {"WWW-Authenticate": "APIKey"},
            )
        if not principal.allows(scope):
            raise Problem(
                403,
                f"this API key has scope '{principal.scope}'; this request needs '{scope}'",
                "X-API-Key",
            )
    wait = state.limiter.acquire(principal.id)
    if wait:
        raise Problem(
            429,
            "rate limit exceeded for this API key; slow down",
            "X-API-Key",
            {"Retry-After": retry_after(wait)},
        )
    request.scope.setdefault("state", {})["principal"] = principal  # request.state.principal
    return principal


API_KEY_HEADER = api_key_header.model.name.lower().encode("latin-1")


def _access(scope: str):
    async def check(
        request: Request, key: Annotated[str | None, Security(api_key_header)]
    ) -> Principal:
        return authorize(request, key, scope)

    check.__name__ = f"require_{scope}"
    return check


JSON = "application/json"
NPY = "application/x-npy"


def media_type(request: Request, accepted: tuple[str, ...]) -> str:
    """The body's media type (``Content-Type`` without parameters) when it is one of
    ``accepted``; a 415 naming them otherwise. A request without a body needs none."""
    given = header(request, b"content-type")
    if given is None:
        length = header(request, b"content-length")
        if (length is None or length == "0") and header(request, b"transfer-encoding") is None:
            return accepted[0]
        raise Problem(
            415, f"the body has no Content-Type; send one of: {', '.join(accepted)}", "Content-Type"
        )
    kind = given.split(";", 1)[0].strip().lower()
    if kind not in accepted:
        raise Problem(
            415,
            f"Content-Type {kind or '(empty)'!r} is not accepted here; send one "
            f"of: {', '.join(accepted)}",
            "Content-Type",
        )
    return kind


async def require_json(request: Request) -> None:
    media_type(request, (JSON,))


class Recognizing(NamedTuple):
    model: LoadedModel
    service: RecognitionService


async def get_recognizing(request: Request) -> Recognizing:
    """All that ``POST /v1/recognize`` needs (read access, the model, the service) as one
    dependency. It is the hot path: FastAPI spends ~15 µs resolving each dependency, and
    the five of the separate ones were a fifth of a single-sample request's CPU. The key
    is read from the header here; the route documents the same security scheme."""
    state = service(request)
    authorize(request, header(request, API_KEY_HEADER), "read", state)
    model = state.holder.current  # current_model(request), the state at hand
    if model is None:
        raise await _no_model(state)
    return Recognizing(model, state.recognition)


# one function object per scope, so a route depending on one twice runs it once
require_read = _access("read")
require_enroll = _access("enroll")
require_admin = _access("admin")


class Idempotency:
    """The ``Idempotency-Key`` of a write: replays a stored answer, or stores a new one
    in the transaction that makes the enrollment."""

    def __init__(self, principal: str, key: str | None, fingerprint: str) -> None:
        self.principal, self.key, self.fingerprint = principal, key, fingerprint

    def replay(self, session: Session) -> None:
        """Raise the stored answer when this key was used before (422 if for another body)."""
        if self.key is None:
            return
        row = repo.get_idempotency(session, self.principal, self.key)
        if row is None:
            return
        if not hmac.compare_digest(row.fingerprint, self.fingerprint):
            raise Problem(
                422,
                "this Idempotency-Key was used for a different request; use a new key",
                "Idempotency-Key",
            )
        headers = {"Idempotent-Replayed": "true"}
        if row.location:
            headers["Location"] = row.location
        raise Replay(JSONResponse(row.body, status_code=row.status_code, headers=headers))

    def save(
        self, session: Session, status: int, body: BaseModel, location: str | None = None
    ) -> None:
        if self.key is not None:
            data = body.model_dump(mode="json", by_alias=True)
            repo.add_idempotency(
                session, self.principal, self.key, self.fingerprint, status, data, location
            )

    @contextmanager
    def writing(
        self, session: Session, recheck: Callable[[], None] | None = None
    ) -> Iterator[None]:
        """Around a write route's changes: a unique constraint broken by a concurrent request
        replays that request's answer when it was a retry with this key, or lets ``recheck``
        name the conflict (a 409), before the error is raised as it is."""
        try:
            yield
        except IntegrityError:
            session.rollback()
            self.replay(session)
            if recheck is not None:
                recheck()
            raise

    def accept(self, session: Session, body: BaseModel, job_id: int, response: Response) -> None:
        """Commit the changes with their 202 answer (kept for retries with this key), which
        points at the job."""
        location = f"/v1/jobs/{job_id}"
        self.save(session, 202, body, location)
        session.commit()
        response.headers["Location"] = location


class Replay(Exception):  # noqa: N818 - not an error: carries the stored answer
    def __init__(self, response: JSONResponse) -> None:
        self.response = response


async def replay_handler(_request: Request, exc: Replay) -> JSONResponse:
    return exc.response


async def get_idempotency(
    request: Request,
    principal: Annotated[Principal, Depends(require_enroll)],
    key: Annotated[
        str | None,
        Header(
            alias="Idempotency-Key",
            min_length=1,
            max_length=200,
            pattern=r"^[\x21-\x7e]+$",
            description="Any unique string (e.g. a UUID): a retry with the same key and body gets "
            "the first answer instead of enrolling twice; the same key with another body is a 422.",
        ),
    ] = None,
) -> Idempotency:
    if key is None:
        return Idempotency(principal.id, None, "")
    body = await request.body()
    try:  # the same JSON however it is spaced
        canonical = json.dumps(json.loads(body), sort_keys=True, separators=(",", ":")).encode()
    except (ValueError, UnicodeDecodeError):
        canonical = body
    digest = hashlib.sha256(f"{request.method} {request.url.path}\n".encode() + canonical)
    return Idempotency(principal.id, key, digest.hexdigest())


# ids fit a 32-bit INTEGER column on every backend; beyond that is a 422, not a database error
MAX_ROW_ID = 2_147_483_647
RowId = Annotated[int, Path(ge=1, le=MAX_ROW_ID)]
PAGE_DEFAULT, PAGE_MAX = 100, 1000


class Page(NamedTuple):
    after: int | None
    limit: int

    def cut(self, rows: list, key) -> tuple[list, int | None]:
        """``rows`` read with a limit of ``limit + 1``: this page's rows, and the
        ``next_after`` cursor (None when the extra row did not come: the last page)."""
        page = rows[: self.limit]
        return page, (key(page[-1]) if len(rows) > self.limit else None)


async def get_page(
    after: Annotated[
        int | None,
        Query(
            ge=0,
            le=MAX_ROW_ID,
            description="Return the rows after this one: the `next_after` of the previous page.",
        ),
    ] = None,
    limit: Annotated[
        int, Query(ge=1, le=PAGE_MAX, description="Most rows in the page.")
    ] = PAGE_DEFAULT,
) -> Page:
    return Page(after, limit)


SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]
HolderDep = Annotated[ModelHolder, Depends(get_holder)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
ExportsDep = Annotated[ExportCache, Depends(get_exports)]
JobWatchDep = Annotated[JobWatch, Depends(get_job_watch)]
RecognizingDep = Annotated[Recognizing, Depends(get_recognizing)]
ModelDep = Annotated[LoadedModel, Depends(get_model)]
OptionalModelDep = Annotated[LoadedModel | None, Depends(get_optional_model)]
# the caller of a write, for the jobs it queues (the same dependency as EnrollAccess: run once)
Enroller = Annotated[Principal, Depends(require_enroll)]
ReadAccess = Depends(require_read)
EnrollAccess = Depends(require_enroll)
AdminAccess = Depends(require_admin)
JsonBody = Depends(require_json)  # 415 for a body that is not JSON
IdempotencyDep = Annotated[Idempotency, Depends(get_idempotency)]
PageDep = Annotated[Page, Depends(get_page)]


@functools.cache
def get_interpreter() -> TextInterpreter:
    """The process's reader of descriptions in words; its sentence-embedding model loads on
    the first text that needs it."""
    return TextInterpreter()


InterpreterDep = Annotated[TextInterpreter, Depends(get_interpreter)]
