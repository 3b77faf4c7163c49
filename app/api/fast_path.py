"""``POST /v1/recognize`` answered without FastAPI's routing: the route robots call most.

Robots send one touch at a time, hundreds of times a second, and a single-sample request
spent about a third of the service's CPU in FastAPI's layers between the server and the
route: its exit stack, matching the route among all the app's routes, resolving its
(absent) parameters, a ``Response`` object. This middleware, the outermost of the app's
own, sends that one route to a small ASGI app composed of the same parts the app's stack
is built of, and everything else down the usual stack:

- the app's own middleware below this one (``RequestMetrics``, ``CORSMiddleware`` when
  configured, ``BodySizeLimit``), the same classes with the same options, in the same
  order, taken from ``app.user_middleware`` as Starlette builds its stack;
- Starlette's ``ExceptionMiddleware`` with the app's exception handlers (all but the 500
  one, which ``ServerErrorMiddleware`` above this middleware keeps), as Starlette gives it;
- an endpoint that marks the FastAPI route as the matched one (``scope["route"]``, as the
  router does: ``RequestMetrics`` counts the request under its template) and answers with
  the same ``answer`` the route calls (the same checks, in the same order, same errors).

So every answer, header and metric is the route's own, through public APIs only. The
FastAPI route stays: it documents the operation, and answers when this is off (with
OpenTelemetry, whose spans name the route FastAPI's router selected).
"""

from __future__ import annotations

from starlette.middleware.exceptions import ExceptionMiddleware
from starlette.requests import Request
from starlette.types import ASGIApp, Receive, Scope, Send

from app.api.routes import recognize
from app.api.routes.recognize import answer

PATH = "/v1/recognize"
_JSON_HEADERS = [(b"content-type", b"application/json")]


class RecognizeFastPath:
    """``app``: the rest of the app's stack, for every other request."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.route_app: ASGIApp | None = None  # built on the first request, as Starlette's stack

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope["path"] != PATH
            or scope["method"] != "POST"
            or scope.get("root_path")
        ):
            await self.app(scope, receive, send)
            return
        if self.route_app is None:
            self.route_app = route_app(scope["app"])
        await self.route_app(scope, receive, send)


def route_app(app) -> ASGIApp:
    """The recognize route's own ASGI app, composed from ``app``'s parts (see the module
    docstring)."""
    # the FastAPI route itself, as the router puts it in the scope
    (route,) = (r for r in recognize.router.routes if r.path == PATH and "POST" in r.methods)

    async def endpoint(scope: Scope, receive: Receive, send: Send) -> None:
        scope["route"] = route
        body = await answer(Request(scope, receive))
        await send(
            {
                "type": "http.response.start",
                "status": 200,
                "headers": [(b"content-length", str(len(body)).encode()), *_JSON_HEADERS],
            }
        )
        await send({"type": "http.response.body", "body": body})

    handlers = {k: v for k, v in app.exception_handlers.items() if k not in (500, Exception)}
    out: ASGIApp = ExceptionMiddleware(endpoint, handlers=handlers, debug=app.debug)
    middleware = app.user_middleware  # outermost first
    at = next(i for i, m in enumerate(middleware) if m.cls is RecognizeFastPath)
    for cls, args, kwargs in reversed(middleware[at + 1 :]):
        out = cls(out, *args, **kwargs)
    return out
