"""RFC 9457 problem details: every error leaves as ``application/problem+json``.

The body carries ``type``, ``title``, ``status``, ``detail``, ``instance`` and
an ``errors`` list of ``{"field", "reason"}`` naming what was wrong. Stack
traces and SQL never leave the process.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
from collections.abc import Iterator, Sequence
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.framework.errors import (
    AttributeVectorError,
    BundleError,
    DuplicateClassError,
    FrameworkError,
    InputKindError,
    InputShapeError,
    NonFiniteInputError,
    NotFittedError,
    TrialInputError,
    UnknownClassError,
    UnsupportedOperationError,
)
from app.service.enrolment import (
    Conflict,
    EnrolmentError,
    Invalid,
    NotFound,
    ReaderUnavailable,
)

log = logging.getLogger(__name__)

MEDIA_TYPE = "application/problem+json"

# framework error -> (status, field named when the route did not name one)
FRAMEWORK_STATUS: dict[type[FrameworkError], tuple[int, str]] = {
    InputKindError: (409, "samples"),  # raw trials for a model of samples, or the reverse
    TrialInputError: (422, "trials"),
    InputShapeError: (422, "samples"),
    NonFiniteInputError: (422, "samples"),
    AttributeVectorError: (422, "attributes"),
    DuplicateClassError: (409, "name"),
    UnknownClassError: (404, "class"),
    BundleError: (409, "version"),
    NotFittedError: (503, "model"),
    UnsupportedOperationError: (409, "model"),  # the served method cannot do it
}

# enrolment rule broken (app.service.enrolment) -> status
ENROLMENT_STATUS: dict[type[EnrolmentError], int] = {
    NotFound: 404,
    Conflict: 409,
    Invalid: 422,
    ReaderUnavailable: 503,
}


class Problem(HTTPException):
    """An HTTPException that names the field at fault."""

    def __init__(
        self,
        status: int,
        detail: str,
        field: str | None = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(status, detail, headers)
        # the field is named beside the reason: "target_confidence: ..." says it once
        reason = detail.removeprefix(f"{field}: ") if field else detail
        self.errors = [{"field": field, "reason": reason}] if field else []


def body_too_large(max_bytes: int) -> Problem:
    """The 413 of a body over the ``max_bytes`` cap."""
    return Problem(413, f"request body is larger than {max_bytes} bytes", "body")


def not_found(what: str, field: str, value: Any) -> Problem:
    return Problem(404, f"no {what} with {field} {value}", field)


# errors about the served model, not about the request: they keep naming the model
ABOUT_THE_MODEL = (NotFittedError, UnsupportedOperationError, BundleError)


@contextlib.contextmanager
def blame(field: str, one: bool = False) -> Iterator[None]:
    """Framework errors about the request raised inside name ``field`` (e.g. 'sample'
    rather than 'samples'). ``one``: the framework saw ``field`` as a batch of one, so its
    "sample 0" and "cell [0][3][4]" are ``field`` and ``field[3][4]``."""
    try:
        yield
    except FrameworkError as exc:
        if isinstance(exc, TrialInputError):  # it knows the place: trials[2].fingers[1].pac
            exc.field = exc.field.replace("trials", field, 1)
        elif not isinstance(exc, ABOUT_THE_MODEL):
            exc.field = field
        if one and isinstance(exc, NonFiniteInputError) and exc.args:
            said = str(exc.args[0]).replace("cell [0]", f"cell {field}")
            exc.args = (re.sub(r"\bsample 0\b", field, said), *exc.args[1:])
        raise


class ProblemResponse(JSONResponse):
    media_type = MEDIA_TYPE


def problem_response(
    request: Request,
    status: int,
    detail: str,
    errors: Sequence[dict[str, Any]] = (),
    headers: dict[str, str] | None = None,
) -> ProblemResponse:
    body = problem_body(status, detail, request.url.path, errors)
    return ProblemResponse(body, status_code=status, headers=headers)


def problem_body(
    status: int, detail: str, instance: str | None, errors: Sequence[dict[str, Any]] = ()
) -> dict[str, Any]:
    """The RFC 9457 body of a problem (the ROS 2 bridge answers with it too)."""
    return {
        "type": "about:blank",
        "title": HTTPStatus(status).phrase,
        "status": status,
        "detail": detail,
        "instance": instance,
        "errors": list(errors),
    }


def framework_problem(exc: FrameworkError, instance: str | None) -> dict[str, Any]:
    """The body a framework error is answered with (``framework_exception_handler``)."""
    status, default_field = next(
        (v for cls, v in FRAMEWORK_STATUS.items() if isinstance(exc, cls)), (422, "body")
    )
    field = getattr(exc, "field", None) or default_field
    return problem_body(status, str(exc), instance, [{"field": field, "reason": str(exc)}])


def field_name(loc: Sequence[Any]) -> str:
    """('body', 'samples', 0, 3) -> 'samples[0][3]'; ('path', 'class_id') -> 'class_id'.

    Pydantic's names for the members of a union (``list[list[float]]``, ``function-after[…]``)
    are left out: they name the validator's internals, not the request."""
    parts = list(loc[1:]) if loc and loc[0] in ("body", "path", "query", "header") else list(loc)
    parts = [p for p in parts if not _union_member(p)]
    if not parts:
        return "body"
    out = str(parts[0])
    for p in parts[1:]:
        out += f"[{p}]" if isinstance(p, int) else f".{p}"
    return out


def _union_member(part: Any) -> bool:
    return isinstance(part, str) and ("[" in part or part in _SCALAR_TYPES)


_SCALAR_TYPES = frozenset({"int", "float", "str", "bool", "none", "bytes"})

# pydantic error type -> what a person reads
_REASONS = {
    "float_parsing": "not a number",
    "float_type": "not a number",
    "finite_number": "not a finite number",
    "int_parsing": "not a whole number",
    "int_type": "not a whole number",
    "int_from_float": "not a whole number",
    "list_type": "not a list",
    "string_type": "not a string",
    "bool_type": "not true or false",
    "bool_parsing": "not true or false",
    "model_type": "not an object",
    "dict_type": "not an object",
    "model_attributes_type": "not an object",
    "missing": "required",
    "extra_forbidden": "not a field of this request",
    # pydantic's constraints, in the service's words (its ctx fills the braces)
    "too_short": "at least {min_length} item(s) needed",
    "too_long": "at most {max_length} item(s) taken",
    "string_too_short": "at least {min_length} character(s) needed",
    "string_too_long": "at most {max_length} character(s) taken",
    "string_pattern_mismatch": "a control character{comma} is not allowed here",
    "less_than_equal": "at most {le}",
    "less_than": "less than {lt}",
    "greater_than_equal": "at least {ge}",
    "greater_than": "more than {gt}",
    "literal_error": "one of {expected}",
    "enum": "one of {expected}",
}
# reasons that are about the value, which is then shown: "(got null)"
_SHOWN = frozenset(_REASONS) - {"missing", "extra_forbidden"}
# at most this many distinct problems per answer: a batch with 992 bad values is one problem
MAX_ERRORS = 5


def _validation_reason(err: dict[str, Any]) -> str:
    if err.get("type") == "json_invalid":
        return f"malformed JSON: {err.get('ctx', {}).get('error', 'cannot be parsed')}"
    if err.get("type") == "value_error":  # our validators' own words, without pydantic's prefix
        return str(err.get("ctx", {}).get("error", err.get("msg", "invalid")))
    reason = _REASONS.get(err.get("type", ""))
    if reason is None:
        return str(err.get("msg", "invalid"))
    ctx = {k: _json(v) if k != "expected" else v for k, v in err.get("ctx", {}).items()}
    if err.get("type") == "string_pattern_mismatch":
        ctx["comma"] = " or a comma" if "," in str(ctx.get("pattern", "")) else ""
    try:
        reason = reason.format(**ctx)
    except (KeyError, IndexError, ValueError):  # a constraint without the context we name
        return str(err.get("msg", "invalid"))
    return re.sub(r"\b1 (\w+)\(s\)", r"1 \1", reason).replace("(s)", "s")


def _json(value: Any) -> str:
    """``value`` as JSON writes it (``null``, ``true``, ``"x"``), not as Python does."""
    try:
        return json.dumps(value, ensure_ascii=False, allow_nan=True)
    except (TypeError, ValueError):
        return repr(value)


def _value_shown(err: dict[str, Any]) -> str:
    if err.get("type") not in _SHOWN or "input" not in err:
        return ""
    shown = _json(err["input"])
    return f" (got {shown if len(shown) <= 40 else shown[:37] + '...'})"


def _closest_union_member(errors: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Of a union's failed members, keep the one the value came closest to matching.

    A sample is ``list[list[float]] | list[float]``; a bad value fails both, and pydantic
    reports both. The member whose errors lie deepest in the value is the shape the client
    meant (ties: the one with fewer errors)."""
    groups: dict[tuple, dict[str, list[dict[str, Any]]]] = {}
    kept = []
    for err in errors:
        loc = tuple(err.get("loc", ()))
        at = next((i for i, p in enumerate(loc) if _union_member(p)), None)
        if at is None:
            kept.append(err)
        else:
            groups.setdefault(loc[:at], {}).setdefault(loc[at], []).append(err)
    for members in groups.values():
        best = max(
            members.values(), key=lambda errs: (max(len(e["loc"]) for e in errs), -len(errs))
        )
        kept.extend(
            _closest_union_member(
                [
                    {
                        **e,
                        "loc": tuple(
                            p for i, p in enumerate(e["loc"]) if i != _first_union(e["loc"])
                        ),
                    }
                    for e in best
                ]
            )
        )
    return kept


def _first_union(loc: Sequence[Any]) -> int:
    return next(i for i, p in enumerate(loc) if _union_member(p))


def readable_errors(errors: Sequence[dict[str, Any]]) -> list[dict[str, str]]:
    """Pydantic's errors as at most ``MAX_ERRORS`` ``{"field", "reason"}`` entries, one per
    distinct problem: the same reason at the same place of each sample (``samples[*][*]``)
    is one problem, named at its first occurrence with a count of the others."""
    problems: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for err in _closest_union_member(errors):
        # a JSON syntax error's location is a character offset, not a field
        name = "body" if err.get("type") == "json_invalid" else field_name(err.get("loc", ()))
        reason = _validation_reason(err)
        place = "".join(
            "[*]" if isinstance(p, int) else f".{p}"
            for p in err.get("loc", ())
            if not _union_member(p)
        )
        problems.setdefault((place, reason), []).append((name, reason + _value_shown(err)))
    out = []
    for same in list(problems.values())[:MAX_ERRORS]:
        name, reason = same[0]
        if len(same) > 1:
            reason += f"; {len(same) - 1} more like it"
        out.append({"field": name, "reason": reason})
    return out


async def http_exception_handler(request: Request, exc: StarletteHTTPException) -> ProblemResponse:
    errors = getattr(exc, "errors", [])
    return problem_response(request, exc.status_code, str(exc.detail), errors, exc.headers)


async def validation_exception_handler(
    request: Request, exc: RequestValidationError
) -> ProblemResponse:
    errors = readable_errors(exc.errors())
    model = request.app.state.service.holder.current
    about_samples = model is not None and any(e["field"].startswith("sample") for e in errors)
    partial = request.url.path.endswith(PARTIAL_SAMPLE_ROUTES)  # under any root path
    by_shape = []
    if about_samples:  # a sample's shape says more than the value pydantic stopped at
        from app.api.sample_input import explain  # it raises Problem: imported here

        rec = model.recognizer
        by_shape = explain(exc.body, rec.input_shape, rec.procedures, partial)
        named = {e["field"] for e in by_shape}
        errors = by_shape + [e for e in errors if not _within(e["field"], named)]
    first = errors[0] if errors else {"field": "body", "reason": "invalid request"}
    detail = f"{first['field']}: {first['reason']}"
    if about_samples and not by_shape:
        detail += f"; one sample has shape {list(model.recognizer.input_shape)}"
        if "(got null)" in first["reason"] and partial and model.recognizer.procedures:
            detail += (
                ": a procedure not done yet is null as whole rows (`procedure_rows` of "
                "GET /v1/models/active), or rows of null or NaN cells; a row with some "
                "numbers needs all of them"
            )
    return problem_response(request, 422, detail, errors[:MAX_ERRORS])


# the routes whose samples may lack procedures (null rows); enrolment takes whole samples
PARTIAL_SAMPLE_ROUTES = ("/v1/recognize", "/v1/describe")


def _within(field: str, named: set[str]) -> bool:
    """Whether ``field`` (``samples[0][3]``) lies in one of the fields ``named``."""
    return any(field == n or field.startswith((f"{n}[", f"{n}.")) for n in named)


async def framework_exception_handler(request: Request, exc: FrameworkError) -> ProblemResponse:
    body = framework_problem(exc, request.url.path)
    headers = {"Retry-After": "5"} if body["status"] == 503 else None
    return ProblemResponse(body, status_code=body["status"], headers=headers)


async def enrolment_exception_handler(request: Request, exc: EnrolmentError) -> ProblemResponse:
    """A broken enrolment rule, answered as a ``Problem`` raised in its place would be."""
    status = next((v for cls, v in ENROLMENT_STATUS.items() if isinstance(exc, cls)), 422)
    errors = [{"field": exc.field, "reason": str(exc)}] if exc.field else []
    return problem_response(request, status, str(exc), errors)


async def store_unavailable_handler(request: Request, exc: OperationalError) -> ProblemResponse:
    """A timed-out statement or an unreachable database: retryable, and no SQL leaves. A
    full disk (SQLite's "database or disk is full", PostgreSQL's "No space left on
    device") is 507: retrying helps only once an operator frees space."""
    log.warning("store error on %s %s: %s", request.method, request.url.path, exc.orig)
    message = str(exc.orig).lower()
    if "disk is full" in message or "no space left" in message:
        return problem_response(
            request,
            507,
            "the store's disk is full; nothing was written: try again once space is freed",
            [],
            {"Retry-After": "60"},
        )
    return problem_response(
        request,
        503,
        "the store is busy or unreachable; try again shortly",
        [],
        {"Retry-After": "1"},
    )


async def unhandled_exception_handler(request: Request, exc: Exception) -> ProblemResponse:
    log.error("unhandled error on %s %s", request.method, request.url.path, exc_info=exc)
    return problem_response(request, 500, "internal error; the service log has the details")


def install(app: FastAPI) -> None:
    app.add_exception_handler(StarletteHTTPException, http_exception_handler)
    app.add_exception_handler(RequestValidationError, validation_exception_handler)
    app.add_exception_handler(FrameworkError, framework_exception_handler)
    app.add_exception_handler(EnrolmentError, enrolment_exception_handler)
    app.add_exception_handler(OperationalError, store_unavailable_handler)
    app.add_exception_handler(Exception, unhandled_exception_handler)


class ProblemError(BaseModel):
    field: str = Field(
        description="What was wrong: a body path such as `samples[0][3]`, a "
        "parameter, or a header such as `X-API-Key`."
    )
    reason: str


class ProblemDetails(BaseModel):
    """An RFC 9457 problem: every error of the service has this body."""

    type: str = Field("about:blank", description="Always `about:blank`: `status` says it all.")
    title: str = Field(description="The status code's phrase.")
    status: int
    detail: str = Field(description="What went wrong, for a person.")
    instance: str | None = Field(None, description="The request's path.")
    errors: list[ProblemError] = Field(
        default_factory=list, description="Each thing the request got wrong, by field."
    )


class ValidationProblem(ProblemDetails):
    """A 422: the request's content is not what the route takes. At most a handful of
    `errors`, one per distinct problem."""

    errors: list[ProblemError] = Field(min_length=1)


# component name -> model; app/api/openapi.py adds them to the schema
COMPONENTS: dict[str, type[BaseModel]] = {
    "Problem": ProblemDetails,
    "ValidationProblem": ValidationProblem,
}


def _component(status: int) -> str:
    return "ValidationProblem" if status == 422 else "Problem"


def responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI entries for the problem responses a route can give, each a reference to
    one shared component (so client generators make one model, not one per response)."""
    return {
        s: {
            "description": HTTPStatus(s).phrase,
            "content": {MEDIA_TYPE: {"schema": {"$ref": f"#/components/schemas/{_component(s)}"}}},
        }
        for s in statuses
    }
