"""What the service takes from uvicorn, Starlette and FastAPI beyond their documented use is
still there, and the installed versions lie within pyproject.toml's bounds.

``app/server/http_protocol.py`` subclasses uvicorn's httptools protocol (its
``connection_made`` and ``loop``), ``app/server/processes.py`` uvicorn's ``Server`` (its
``startup``/``shutdown`` with sockets and ``started``), and ``RequestMetrics`` and
``app/api/fast_path.py`` rely on Starlette's router naming the matched route in
``scope["route"]``, on ``Middleware`` unpacking to (class, args, kwargs) and on
``ExceptionMiddleware(app, handlers, debug)``. pyproject.toml caps each package below its
next release that may break these; this test says which part broke when a bound is raised."""

from __future__ import annotations

import inspect
import re
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
CAPPED = ("starlette", "fastapi", "uvicorn")


def requirements() -> dict[str, Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    out = {}
    for line in project["dependencies"]:
        req = Requirement(line)
        out[req.name] = req
    return out


@pytest.mark.parametrize("name", CAPPED)
def test_installed_versions_lie_within_the_bounds(name):
    req = requirements().get(name)
    assert req is not None, f"pyproject.toml names no bound for {name}"
    assert any(s.operator == "<" for s in req.specifier), f"{name} has no upper bound"
    installed = version(name)
    assert req.specifier.contains(installed, prereleases=True), (
        f"{name} {installed} is outside pyproject.toml's {req.specifier}: check what "
        "tests/test_dependency_internals.py lists before moving the bound"
    )


def test_uvicorn_protocol_and_server_hooks_exist():
    from uvicorn import Server
    from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

    made = inspect.signature(HttpToolsProtocol.connection_made)
    assert list(made.parameters) == ["self", "transport"], (
        "uvicorn's HttpToolsProtocol.connection_made changed: app/server/http_protocol.py "
        "hands it a wrapped transport"
    )
    assert re.search(r"self\.loop\s*=", inspect.getsource(HttpToolsProtocol.__init__)), (
        "uvicorn's HttpToolsProtocol no longer keeps self.loop: app/server/http_protocol.py "
        "schedules its flush on it"
    )
    for hook in ("startup", "shutdown"):
        params = inspect.signature(getattr(Server, hook)).parameters
        assert "sockets" in params, (
            f"uvicorn's Server.{hook} no longer takes sockets: app/server/processes.py overrides it"
        )
    assert "self.started" in inspect.getsource(Server), (
        "uvicorn's Server no longer sets started: app/server/processes.py reads it"
    )


def test_starlette_names_the_route_and_composes_middleware():
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.middleware.exceptions import ExceptionMiddleware
    from starlette.responses import PlainTextResponse
    from starlette.routing import Route
    from starlette.testclient import TestClient

    seen = {}

    async def endpoint(request):
        seen["route"] = request.scope.get("route")
        return PlainTextResponse("ok")

    route = Route("/x", endpoint, methods=["POST"])
    assert TestClient(Starlette(routes=[route])).post("/x").text == "ok"
    assert seen["route"] is route, (
        "Starlette's router no longer sets scope['route']: RequestMetrics (app/api/main.py) "
        "and app/api/fast_path.py count requests under it"
    )

    class Wrapper:
        def __init__(self, app, tag):
            self.app, self.tag = app, tag

    cls, args, kwargs = Middleware(Wrapper, tag=1)
    assert (cls, args, kwargs) == (Wrapper, (), {"tag": 1}), (
        "starlette.middleware.Middleware no longer unpacks to (class, args, kwargs): "
        "app/api/fast_path.py builds the route's app from app.user_middleware"
    )
    params = inspect.signature(ExceptionMiddleware).parameters
    assert {"app", "handlers", "debug"} <= set(params), (
        "Starlette's ExceptionMiddleware(app, handlers, debug) changed: app/api/fast_path.py "
        "builds one"
    )
