"""Schemathesis against the service's own OpenAPI document, with API keys, at benchmark size.

    .venv/bin/python -m bench.fuzz                      # SQLite, >= 10,000 requests
    .venv/bin/python -m bench.fuzz --postgres postgresql://postgres@127.0.0.1:5432/test

In process (ASGI) on a fresh store with the quick test model, a key of each scope stored
(so a request without one is a 401), two passes:

1. every operation on its own: generated cases, valid and invalid, each sent without a key
   or with a key of a scope drawn from read, enroll and admin;
2. stateful scenarios along the document's OpenAPI links (``app/api/openapi.py``): register
   a class, add a sample to it, read it back, recognise it, withdraw it and the class; add
   an attribute, register a class described by it, retire it; each step sent with the admin
   key, and once more before that with a key of too small a scope (or none), which must be
   refused and leave the store as it was (no job queued, the same active version).

Every response is checked: no 5xx; its status code, content type and promised headers are
documented; its body matches the documented schema (2xx bodies and problems alike); every
4xx is application/problem+json; 401 without a valid key, 403 exactly where the key's scope
is below the operation's (read < enroll < admin), neither otherwise. Two answers before the
key are counted apart, not as failures: a JSON body FastAPI cannot read (400, or 422 for a
syntax error; it parses the body before any dependency runs) and a path parameter holding a
line break (the router's 404). Bodies that take samples, attribute names or class names are
given real ones half the time (a generator cannot guess 32 x 30 numbers or the vocabulary),
so recognition and enrolment get past 422. Exit 1 on any failure.
tests/api/test_api_fuzz.py is the bounded CI run of the same harness.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.errors import Flaky, FlakyStrategyDefinition

SCOPES = ("read", "enroll", "admin")  # each allows what the ones before it allow
# operation -> the scope it needs (None: open, no key needed); app/api/deps.py and the routes
NEEDS: dict[str, str | None] = {
    "GET /healthz": None,
    "GET /readyz": None,
    "GET /metrics": None,
    "POST /v1/recognize": "read",
    "POST /v1/describe": "read",
    "GET /v1/attributes": "read",
    "POST /v1/attributes": "admin",
    "POST /v1/attributes/interpret": "read",
    "DELETE /v1/attributes/{name}": "admin",
    "GET /v1/classes": "read",
    "POST /v1/classes": "enroll",
    "GET /v1/classes/{class_id}": "read",
    "PATCH /v1/classes/{class_id}": "enroll",
    "DELETE /v1/classes/{class_id}": "enroll",
    "GET /v1/classes/{class_id}/samples": "read",
    "POST /v1/classes/{class_id}/samples": "enroll",
    "GET /v1/classes/{class_id}/samples/{sample_id}": "read",
    "DELETE /v1/classes/{class_id}/samples/{sample_id}": "enroll",
    "GET /v1/jobs": "read",
    "GET /v1/jobs/{job_id}": "read",
    "GET /v1/models": "read",
    "GET /v1/models/active": "read",
    "GET /v1/models/{version}": "read",
    "GET /v1/models/active/bundle": "read",
    "GET /v1/models/{version}/bundle": "read",
    "POST /v1/models/{version}/activate": "admin",
    "POST /v1/models/choice": "admin",
}
PROBLEM = "application/problem+json"


def _checks() -> list[Callable]:
    from schemathesis.checks import not_a_server_error
    from schemathesis.specs.openapi.checks import (
        content_type_conformance,
        response_headers_conformance,
        response_schema_conformance,
        status_code_conformance,
    )

    return [
        not_a_server_error,
        status_code_conformance,
        content_type_conformance,
        response_headers_conformance,
        response_schema_conformance,
    ]


# schemathesis check -> the figure it counts in
KINDS = {
    "not_a_server_error": "5xx",
    "status_code_conformance": "undocumented status",
    "content_type_conformance": "undocumented content type",
    "response_headers_conformance": "missing or wrong header",
    "response_schema_conformance": "schema violation",
}


def expected_auth(label: str, scope: str | None) -> int | None:
    """The status a request with a key of ``scope`` (None: no key) must get before anything
    else is looked at: 401, 403, or None (neither may come)."""
    needs = NEEDS[label]
    if needs is None:
        return None
    if scope is None:
        return 401
    return 403 if SCOPES.index(scope) < SCOPES.index(needs) else None


class Fuzzer:
    """One service's fuzzing: its keys, the checks, and what every response got."""

    def __init__(self, app, keys: dict[str, str], dataset, seconds: float | None = None) -> None:
        import schemathesis
        from schemathesis.config import SchemathesisConfig

        self.app = app
        self.keys = keys
        self.dataset = dataset  # the served model's: real samples and names to steer with
        # the links the document declares, not ones schemathesis infers from names
        config = SchemathesisConfig.from_dict(
            {"phases": {"stateful": {"inference": {"algorithms": []}}}}
        )
        self.schema = schemathesis.openapi.from_asgi("/openapi.json", app, config=config)
        self.schema.hook(self._steering())
        self.schema.hook(_short_waits)
        self.checks = _checks()
        self.statuses: collections.Counter = collections.Counter()
        self.per_operation: collections.Counter = collections.Counter()
        self.violations: collections.Counter = collections.Counter()
        self.failures: list[str] = []
        self.requests = 0
        self.links_followed: collections.Counter = collections.Counter()
        self.scenarios = 0
        self.unreadable_before_key: collections.Counter = collections.Counter()
        self.unroutable_before_key: collections.Counter = collections.Counter()
        self.slow: list[tuple] = []  # requests over a second
        # a budget for CI: no new request after it (the figures say whether it was reached)
        self.deadline = None if seconds is None else time.monotonic() + seconds
        self.stopped_by_time = False
        self.flaky_restarts = 0

    # ------------------------------------------------------------------ requests
    def send(self, case, scope: str | None):
        """``case`` sent with the key of ``scope`` (None: without a key), and checked."""
        case.headers = {k: v for k, v in (case.headers or {}).items() if k.lower() != "x-api-key"}
        response = case.call(headers={"X-API-Key": self.keys[scope]} if scope else {})
        self.check(case, response)
        return response

    def refused(self, case, scope: str | None) -> None:
        """``case`` sent with a key too small for it (or none): besides the checks, a write
        must leave the store as it was (no job queued, the same active version)."""
        write = case.method.upper() != "GET"
        before = self.store_state() if write else None
        response = self.send(case, scope)
        if write and response.status_code in (401, 403) and self.store_state() != before:
            self._record("refused but written", case.operation.label, response, str(before))

    def store_state(self) -> tuple:
        from sqlalchemy import func, select

        from app.store.models import Job, ModelVersion

        with self.app.state.service.sessions() as session:
            jobs = session.scalar(select(func.count()).select_from(Job))
            active = session.scalar(select(ModelVersion.version).where(ModelVersion.active))
        return jobs, active

    def out_of_time(self) -> bool:
        if self.deadline is not None and time.monotonic() > self.deadline:
            self.stopped_by_time = True
        return self.stopped_by_time

    def sent_scope(self, response) -> str | None:
        """The scope of the key the request carried: None without one or with a wrong one
        (an invalid case may leave the header out, which is a 401 too)."""
        sent = response.request.headers.get("X-API-Key")
        return next((scope for scope, key in self.keys.items() if key == sent), None)

    def check(self, case, response) -> None:
        from schemathesis.core.failures import FailureGroup

        label = case.operation.label
        self.requests += 1
        if response.elapsed > 1:
            self.slow.append((round(response.elapsed, 1), label, response.request.path_url[:120]))
        self.statuses[response.status_code] += 1
        self.per_operation[label] += 1
        try:
            case.validate_response(response, checks=self.checks)
        except FailureGroup as group:
            for failure in group.exceptions:
                self._fail(case, response, failure)
        except AssertionError as failure:
            self._fail(case, response, failure)
        content_type = response.headers.get("content-type", [""])[0]
        if 400 <= response.status_code < 500 and content_type != PROBLEM:
            self._record("4xx not problem+json", label, response, content_type)
        scope = self.sent_scope(response)
        expected = expected_auth(label, scope)
        got = response.status_code
        if expected is not None and _unreadable_body(response):
            # FastAPI parses a JSON body before any dependency runs, the key's check included
            self.unreadable_before_key[f"{label} {got} for {expected}"] += 1
        elif expected is not None and _unroutable(response):
            self.unroutable_before_key[label] += 1
        elif (expected is not None and got != expected) or (expected is None and got in (401, 403)):
            self._record(
                "wrong 401/403",
                label,
                response,
                f"key {scope or '(none)'}: expected {expected or 'neither 401 nor 403'}",
            )

    def _fail(self, case, response, failure) -> None:
        title = getattr(failure, "title", type(failure).__name__)
        kind = next((k for name, k in KINDS.items() if _is(failure, name)), title)
        message = getattr(failure, "message", str(failure))
        self._record(kind, case.operation.label, response, f"{title}: {message}")

    def _record(self, kind: str, label: str, response, what: str) -> None:
        self.violations[kind] += 1
        if len(self.failures) < 50:
            body = response.text[:300] if hasattr(response, "text") else ""
            self.failures.append(
                f"{kind}: {label} -> {response.status_code}: {what[:600]} | {body}"
            )

    # ----------------------------------------------------------------- the passes
    def run_operations(self, examples: int) -> None:
        """Pass 1: every operation on its own, valid and invalid cases, each with a key of a
        drawn scope or none."""
        from schemathesis import GenerationMode

        for result in self.schema.get_all_operations():
            operation = result.ok()
            cases = st.one_of(
                operation.as_strategy(generation_mode=GenerationMode.POSITIVE),
                operation.as_strategy(generation_mode=GenerationMode.NEGATIVE),
            )

            @settings(
                max_examples=examples,
                deadline=None,
                database=None,
                suppress_health_check=list(HealthCheck),
            )
            @given(case=cases, scope=st.sampled_from((None, *SCOPES)))
            def exercise(case, scope):
                if not self.out_of_time():
                    self.send(case, scope)

            exercise()

    def run_scenarios(self, scenarios: int, steps: int) -> None:
        """Pass 2: scenarios along the document's links, each step with the admin key, and
        once more before that with a key too small (or none), which must change nothing."""
        fuzzer = self
        too_small = {
            label: [None, *SCOPES[: SCOPES.index(needs)]] if needs else []
            for label, needs in NEEDS.items()
        }

        class Workflow(self.schema.as_state_machine()):
            step_count = 0

            def before_call(self, case) -> None:
                lower = too_small[case.operation.label]
                if lower:
                    Workflow.step_count += 1
                    fuzzer.refused(case, lower[Workflow.step_count % len(lower)])

            def get_call_kwargs(self, case) -> dict[str, Any]:
                case.headers = {
                    k: v for k, v in (case.headers or {}).items() if k.lower() != "x-api-key"
                }
                return {"headers": {"X-API-Key": fuzzer.keys["admin"]}}

            def validate_response(self, response, case, additional_checks=None, **kwargs):
                fuzzer.check(case, response)

            def teardown(self) -> None:
                fuzzer.scenarios += 1

            def step(self, input):
                if fuzzer.out_of_time():
                    raise _OutOfTime
                if input.transition is not None and input.is_applied:
                    fuzzer.links_followed[input.transition.id] += 1
                return super().step(input)

        # The service keeps its state from one scenario to the next, so a step hypothesis
        # replays may answer otherwise than it did (a 202 is a 409 the second time) and the
        # run stops as flaky: go on with a new run until the scenarios are done.
        attempts = 0
        while self.scenarios < scenarios and attempts < scenarios:
            attempts += 1
            done = self.scenarios
            try:
                Workflow.run(
                    settings=settings(
                        max_examples=scenarios - self.scenarios,
                        stateful_step_count=steps,
                        deadline=None,
                        database=None,
                        suppress_health_check=list(HealthCheck),
                    )
                )
            except (Flaky, FlakyStrategyDefinition):
                self.flaky_restarts += 1
            except _OutOfTime:
                break
            if self.scenarios == done:
                break

    # -------------------------------------------------------------- real samples
    def _steering(self):
        """A ``flatmap_body`` hook: a generated body that takes samples, attribute names or
        class names keeps what was generated or, as often, gets real ones: dataset samples of
        the served shape (maybe with noise), names from the vocabulary, the dataset's class
        names. A generator cannot guess 32 x 30 numbers or a vocabulary, and without them
        recognition, enrolment and descriptions would never get past their 422."""
        data = self.dataset
        one = st.tuples(
            st.integers(0, len(data.samples) - 1),
            st.sampled_from((0.0, 0.01, 1.0)),
            st.integers(0, 2**32 - 1),
        ).map(lambda t: _noisy(data.samples[t[0]], t[1], t[2]))
        names = st.lists(st.sampled_from(data.attribute_names), min_size=1, max_size=4, unique=True)
        value = st.sampled_from((0.0, 0.5, 1.0)) | st.floats(0, 1)
        described = names | st.dictionaries(
            st.sampled_from(data.attribute_names), value, min_size=1
        )
        values = st.dictionaries(st.sampled_from(data.class_names), value, max_size=4)

        def samples(body: dict, field: str) -> st.SearchStrategy:
            real = st.lists(one, min_size=1, max_size=4) if field == "samples" else one
            return real.map(lambda x: {**body, field: x})

        def description(body: dict) -> st.SearchStrategy:
            rest = {k: v for k, v in body.items() if k not in ("attributes", "attribute_vector")}
            return described.map(lambda d: {**rest, "attributes": d})

        steer: dict[str, list[Callable[[dict], st.SearchStrategy]]] = {
            "POST /v1/recognize": [lambda b: samples(b, "samples")],
            "POST /v1/describe": [lambda b: samples(b, "samples")],
            "POST /v1/classes": [description, lambda b: samples(b, "samples")],
            "PATCH /v1/classes/{class_id}": [description],
            "POST /v1/classes/{class_id}/samples": [lambda b: samples(b, "sample")],
            "POST /v1/attributes": [lambda b: values.map(lambda v: {**b, "values": v})],
        }

        def flatmap_body(context, body):
            operation = context.operation
            ways = steer.get(operation.label, []) if operation is not None else []
            strategy = st.just(body)
            if isinstance(body, dict):
                for way in ways:
                    strategy = strategy.flatmap(lambda b, way=way: st.just(b) | way(b))
            return strategy

        return flatmap_body

    def report(self, store: str, seconds: float) -> dict[str, Any]:
        return {
            "store": store,
            "requests": self.requests,
            "operations": len(self.per_operation),
            "seconds": round(seconds, 1),
            "statuses": {str(k): v for k, v in sorted(self.statuses.items())},
            "2xx": sum(v for k, v in self.statuses.items() if 200 <= k < 300),
            "5xx": sum(v for k, v in self.statuses.items() if k >= 500),
            "violations": dict(self.violations),
            "schema_violations": self.violations["schema violation"],
            "scenarios": self.scenarios,
            "stopped_by_time": self.stopped_by_time,
            "flaky_restarts": self.flaky_restarts,
            "links_followed": dict(sorted(self.links_followed.items())),
            "unreadable_body_before_key": dict(self.unreadable_before_key),
            "unroutable_path_before_key": dict(self.unroutable_before_key),
            "slowest": sorted(self.slow, reverse=True)[:10],
            "first_failures": self.failures[:20],
        }


def _is(failure, check_name: str) -> bool:
    """Whether ``failure`` came from the schemathesis check ``check_name``."""
    from schemathesis.core.failures import ServerError
    from schemathesis.openapi.checks import (
        JsonSchemaError,
        MissingContentType,
        MissingHeaders,
        UndefinedContentType,
        UndefinedStatusCode,
    )

    kinds = {
        "not_a_server_error": (ServerError,),
        "status_code_conformance": (UndefinedStatusCode,),
        "content_type_conformance": (MissingContentType, UndefinedContentType),
        "response_headers_conformance": (MissingHeaders,),
        "response_schema_conformance": (JsonSchemaError,),
    }
    if check_name == "response_headers_conformance" and isinstance(failure, JsonSchemaError):
        return "header" in getattr(failure, "title", "").lower()
    if check_name == "response_schema_conformance" and isinstance(failure, JsonSchemaError):
        return "header" not in getattr(failure, "title", "").lower()
    return isinstance(failure, kinds[check_name])


def map_query(context, query):
    """No long polls: with no worker running, a job waited for stays queued for all of
    ``wait`` (up to 20 s); the fuzz waits 0.05 s at most."""
    operation = context.operation
    if operation is not None and operation.label == "GET /v1/jobs/{job_id}" and query:
        wait = query.get("wait")
        if isinstance(wait, int | float) and not isinstance(wait, bool) and wait > 0.05:
            query = {**query, "wait": 0.05}
    return query


_short_waits = map_query


class _OutOfTime(Exception):
    pass


def _unroutable(response) -> bool:
    """The router's own 404 for a path parameter holding a line break, which no route's
    pattern matches; no stored name or id holds one (names refuse control characters)."""
    path = unquote(response.request.path_url.split("?", 1)[0])
    return response.status_code == 404 and "\n" in path and response.json().get("errors") == []


def _unreadable_body(response) -> bool:
    """Whether ``response`` says the body could not be read as JSON: a 400 (not UTF-8), or
    a 422 naming a syntax error."""
    if response.status_code == 400:
        return True
    try:
        errors = response.json().get("errors", []) if response.status_code == 422 else []
    except ValueError:
        return False
    return any(e.get("reason", "").startswith("malformed JSON") for e in errors)


def _noisy(sample: np.ndarray, scale: float, seed: int) -> list:
    if scale == 0:
        return sample.tolist()
    noise = np.random.default_rng(seed).normal(0, scale, sample.shape).astype(np.float32)
    return (sample + noise).tolist()


def make_keys(app) -> dict[str, str]:
    """A stored key of each scope; from now on a request without one is a 401."""
    from app.store import repo

    keys = {}
    with app.state.service.sessions.begin() as session:
        for scope in SCOPES:
            keys[scope], _ = repo.create_api_key(session, scope, f"fuzz-{scope}")
    app.state.service.keys.refresh()
    return keys


def fuzz(
    app, dataset, examples: int, scenarios: int, steps: int, seconds: float | None = None
) -> Fuzzer:
    """Both passes on ``app`` (already started), with a key of each scope made for them;
    ``seconds``: a budget, after which no request is sent."""
    fuzzer = Fuzzer(app, make_keys(app), dataset, seconds)
    fuzzer.run_operations(examples)
    fuzzer.run_scenarios(scenarios, steps)
    return fuzzer


def main() -> int:
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.testing.service import fresh_postgres_database, quick_settings, trained_base

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--examples", type=int, default=200, help="generated cases per operation")
    p.add_argument("--scenarios", type=int, default=600, help="stateful scenarios")
    p.add_argument("--steps", type=int, default=12, help="most steps a scenario takes")
    p.add_argument("--postgres", default="", help="admin URL of a PostgreSQL server")
    args = p.parse_args()
    base = trained_base()
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        cfg = quick_settings(Path(tmp) / "data", database_url=url, rate_limit=0)
        app = create_app(cfg, trainer=lambda: base)
        stack.enter_context(TestClient(app))
        started = time.monotonic()
        fuzzer = fuzz(app, base[1], args.examples, args.scenarios, args.steps)
        report = fuzzer.report(
            "postgresql" if args.postgres else "sqlite", time.monotonic() - started
        )
    print(json.dumps(report, indent=2))
    return 1 if fuzzer.violations else 0


if __name__ == "__main__":
    sys.exit(main())
