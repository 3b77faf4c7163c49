"""RFC 9457 problem details: every error leaves as ``application/problem+json``.

The body carries ``type``, ``title``, ``status``, ``detail``, ``instance`` and
an ``errors`` list of ``{"field", "reason"}`` naming what was wrong. Stack
traces and SQL never leave the process.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator, Sequence
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.framework.errors import (
    AttributeVectorError,
    BundleError,
    DuplicateClassError,
    FrameworkError,
    InputShapeError,
    NonFiniteInputError,
    NotFittedError,
    UnknownClassError,
    UnsupportedOperationError,
)

log = logging.getLogger(__name__)

MEDIA_TYPE = "application/problem+json"

# framework error -> (status, field named when the route did not name one)
FRAMEWORK_STATUS: dict[type[FrameworkError], tuple[int, str]] = {
    InputShapeError: (422, "samples"),
    NonFiniteInputError: (422, "samples"),
    AttributeVectorError: (422, "attributes"),
    DuplicateClassError: (409, "name"),
    UnknownClassError: (404, "class"),
    BundleError: (409, "version"),
    NotFittedError: (503, "model"),
    UnsupportedOperationError: (409, "model"),  # the served method cannot do it
}


class Problem(HTTPException):
    """An HTTPException that names the field at fault."""

    def __init__(
        self, status: int, detail: str, field: str | None = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(status, detail, headers)
        self.errors = [{"field": field, "reason": detail}] if field else []


def not_found(what: str, field: str, value: Any) -> Problem:
    return Problem(404, f"no {what} with {field} {value}", field)


# errors about the served model, not about the request: they keep naming the model
ABOUT_THE_MODEL = (NotFittedError, UnsupportedOperationError, BundleError)


@contextlib.contextmanager
def blame(field: str) -> Iterator[None]:
    """Framework errors about the request raised inside name ``field`` (e.g. 'sample'
    rather than 'samples')."""
    try:
        yield
    except FrameworkError as exc:
        if not isinstance(exc, ABOUT_THE_MODEL):
            exc.field = field
        raise


class ProblemResponse(JSONResponse):
    media_type = MEDIA_TYPE


def problem_response(
    request: Request, status: int, detail: str, errors: Sequence[dict[str, Any]] = (),
    headers: dict[str, str] | None = None,
) -> ProblemResponse:
    body = {
        "type": "about:blank",
        "title": HTTPStatus(status).phrase,
        "status": status,
        "detail": detail,
        "instance": request.url.path,
        "errors": list(errors),
    }
    return ProblemResponse(body, status_code=status, headers=headers)


def field_name(loc: Sequence[Any]) -> str:
    """('body', 'samples', 0, 3) -> 'samples[0][3]'; ('path', 'class_id') -> 'class_id'."""
    parts = list(loc[1:]) if loc and loc[0] in ("body", "path", "query", "header") else list(loc)
    if not parts:
        return "body"
    out = str(parts[0])
    for p in parts[1:]:
        out += f"[{p}]" if isinstance(p, int) else f".{p}"
    return out


def _validation_reason(err: dict[str, Any]) -> str:
    if err.get("type") == "json_invalid":
        return f"malformed JSON: {err.get('ctx', {}).get('error', 'cannot be parsed')}"
    return str(err.get("msg", "invalid"))


async def http_exception_handler(request: Request, exc: StarletteHTTPException) -> ProblemResponse:
    errors = getattr(exc, "errors", [])
    return problem_response(request, exc.status_code, str(exc.detail), errors, exc.headers)


async def validation_exception_handler(
    request: Request, exc: RequestValidationError
) -> ProblemResponse:
    errors = []
    for err in exc.errors():
        loc = err.get("loc", ())
        # a JSON syntax error's location is a character offset, not a field
        name = "body" if err.get("type") == "json_invalid" else field_name(loc)
        errors.append({"field": name, "reason": _validation_reason(err)})
    first = errors[0] if errors else {"field": "body", "reason": "invalid request"}
    return problem_response(request, 422, f"{first['field']}: {first['reason']}", errors)


async def framework_exception_handler(request: Request, exc: FrameworkError) -> ProblemResponse:
    status, default_field = next(
        (v for cls, v in FRAMEWORK_STATUS.items() if isinstance(exc, cls)), (422, "body")
    )
    field = getattr(exc, "field", None) or default_field
    headers = {"Retry-After": "5"} if status == 503 else None
    return problem_response(request, status, str(exc), [{"field": field, "reason": str(exc)}], headers)


async def store_unavailable_handler(request: Request, exc: OperationalError) -> ProblemResponse:
    """A timed-out statement or an unreachable database: retryable, and no SQL leaves."""
    log.warning("store error on %s %s: %s", request.method, request.url.path, exc.orig)
    return problem_response(
        request, 503, "the store is busy or unreachable; try again shortly", [],
        {"Retry-After": "1"},
    )


async def unhandled_exception_handler(request: Request, exc: Exception) -> ProblemResponse:
    log.error("unhandled error on %s %s", request.method, request.url.path, exc_info=exc)
    return problem_response(request, 500, "internal error; the service log has the details")


def install(app: FastAPI) -> None:
    app.add_exception_handler(StarletteHTTPException, http_exception_handler)
    app.add_exception_handler(RequestValidationError, validation_exception_handler)
    app.add_exception_handler(FrameworkError, framework_exception_handler)
    app.add_exception_handler(OperationalError, store_unavailable_handler)
    app.add_exception_handler(Exception, unhandled_exception_handler)


def responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI entries for the problem responses a route can give."""
    return {
        s: {"description": HTTPStatus(s).phrase, "content": {MEDIA_TYPE: {"schema": PROBLEM_SCHEMA}}}
        for s in statuses
    }


PROBLEM_SCHEMA = {
    "type": "object",
    "title": "Problem",
    "required": ["type", "title", "status", "detail"],
    "properties": {
        "type": {"type": "string"},
        "title": {"type": "string"},
        "status": {"type": "integer"},
        "detail": {"type": "string"},
        "instance": {"type": "string"},
        "errors": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {"field": {"type": "string"}, "reason": {"type": "string"}},
            },
        },
    },
}
