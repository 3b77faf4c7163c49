"""``POST /v1/recognize`` answered without FastAPI's routing: the route robots call most.

Robots send one touch at a time, hundreds of times a second, and a single-sample request
spent about a third of the service's CPU in the layers between the server and the route:
the exception middleware, FastAPI's exit stack, matching the route, resolving its
(absent) parameters, a ``Response`` object. This middleware, the outermost of the app's
own, answers that one route itself: it calls the same ``answer`` the route calls (the
same checks, in the same order, with the same errors), hands any error to the handler the
app registered for it (as Starlette's exception middleware does), and counts the request
in ``/metrics`` as ``RequestMetrics`` does, under the route's template. Everything else,
and this route whenever it takes more than that (CORS headers, OpenTelemetry spans, a
declared body over the size cap, which ``BodySizeLimit`` answers), goes down the usual
stack. The FastAPI route stays: it documents the operation, and answers when this is off.
"""

from __future__ import annotations

import time
from typing import Any

from starlette._utils import is_async_callable
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.types import ASGIApp, Receive, Scope, Send

from app.api.problems import body_too_large
from app.api.routes.recognize import answer
from app.service.metrics import Metrics

PATH = "/v1/recognize"
_JSON_HEADERS = [(b"content-type", b"application/json")]
_NOT_FOR_US = object()


class RecognizeFastPath:
    """``cors``: CORS is configured, so requests that carry an ``Origin`` header go down the
    stack, through ``CORSMiddleware``."""

    def __init__(self, app: ASGIApp, metrics: Metrics, max_bytes: int, cors: bool = False) -> None:
        self.app = app
        self.metrics = metrics
        self.max_bytes = max_bytes
        self.cors = cors

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope["path"] != PATH
            or scope["method"] != "POST"
            or scope.get("root_path")
        ):
            await self.app(scope, receive, send)
            return
        declared = self._declared_length(scope["headers"])
        if declared is _NOT_FOR_US:
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500  # what an error no handler answers becomes (ServerErrorMiddleware's)
        # a declared length (at most the cap) bounds the body: the server reads no more of
        # it; a body sent without one is counted as it comes, as BodySizeLimit counts it
        request = Request(scope, receive if declared else _counted(receive, self.max_bytes))
        try:
            try:
                body = await answer(request)
            except Exception as exc:
                response = await _handled(request, exc)  # raises what no handler takes
                status = response.status_code
                await response(scope, receive, send)
                return
            status = 200
            await send(
                {
                    "type": "http.response.start",
                    "status": 200,
                    "headers": [(b"content-length", str(len(body)).encode()), *_JSON_HEADERS],
                }
            )
            await send({"type": "http.response.body", "body": body})
        finally:
            self.metrics.observe_request("POST", PATH, status, time.perf_counter() - start)

    def _declared_length(self, headers: list[tuple[bytes, bytes]]) -> bool | object:
        """Whether the request declares its body's length (the first Content-Length, as
        ``Headers.get`` reads it, a number), or ``_NOT_FOR_US``: a declared length over the cap
        (``BodySizeLimit`` answers it, before any byte is read), or an ``Origin`` when
        CORS is configured."""
        declared, length_seen = False, False
        for name, value in headers:
            if name == b"content-length" and not length_seen:
                length_seen = True
                declared = value.isdigit()
                if declared and int(value) > self.max_bytes:
                    return _NOT_FOR_US
            elif name == b"origin" and self.cors:
                return _NOT_FOR_US
        return declared


def _counted(receive: Receive, max_bytes: int) -> Receive:
    """``receive``, refusing a body sent without a length once it grows over the cap (as
    ``BodySizeLimit`` does)."""
    seen = 0

    async def counted() -> dict[str, Any]:
        nonlocal seen
        message = await receive()
        seen += len(message.get("body", b""))
        if seen > max_bytes:
            raise body_too_large(max_bytes)
        return message

    return counted


async def _handled(request: Request, exc: Exception):
    """The response of the handler the app registered for ``exc``, found as Starlette's
    ``ExceptionMiddleware`` finds it (by status code for HTTP exceptions, then by class);
    ``exc`` is raised again when none takes it, for ``ServerErrorMiddleware``."""
    handlers = request.app.exception_handlers
    handler = None
    if isinstance(exc, HTTPException):
        handler = handlers.get(exc.status_code) if exc.status_code != 500 else None
    if handler is None:
        handler = next(
            (
                handlers[cls]
                for cls in type(exc).__mro__
                if cls in handlers and cls is not Exception
            ),
            None,
        )
    if handler is None:
        raise exc
    if is_async_callable(handler):
        return await handler(request, exc)
    return await run_in_threadpool(handler, request, exc)
