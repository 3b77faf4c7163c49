"""A bounded schemathesis run against the service's own OpenAPI schema: no 5xx,
and every 4xx is problem+json. (The long run is a benchmark, not a test.)"""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, given, settings

from tests.service_fixtures import error_contract_breach

EXAMPLES_PER_OPERATION = 15


def test_no_server_errors_and_every_4xx_is_a_problem(app, client):
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    failures, calls = [], []
    for result in schema.get_all_operations():
        operation = result.ok()

        @settings(
            max_examples=EXAMPLES_PER_OPERATION,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        @given(case=operation.as_strategy())
        def exercise(case):
            label = case.operation.label
            response = case.call()
            calls.append(label)
            if breach := error_contract_breach(label, response):
                failures.append(breach)

        exercise()
    assert failures == []
    assert len(set(calls)) >= 12  # every operation was exercised
