"""Schemathesis against the service's own OpenAPI schema, at benchmark size.

    .venv/bin/python -m bench.fuzz --examples 1000     # 12 operations x 1000 >= 10,000 requests

In-process (ASGI) on a fresh SQLite store with the quick test model, or on PostgreSQL
with --postgres URL. Counts every request; fails (exit 1) on any 5xx or any 4xx that is
not application/problem+json. tests/api/test_api_fuzz.py is the bounded CI run.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path


def main() -> int:
    import schemathesis
    from fastapi.testclient import TestClient
    from hypothesis import HealthCheck, given, settings

    from app.api.main import create_app
    from tests.service_fixtures import (
        error_contract_breach,
        fresh_postgres_database,
        quick_settings,
        trained_base,
    )

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--examples", type=int, default=1000, help="generated cases per operation")
    p.add_argument("--postgres", default="")
    args = p.parse_args()
    base = trained_base()
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        cfg = quick_settings(Path(tmp) / "data", database_url=url, rate_limit=0)
        app = create_app(cfg, trainer=lambda: base)
        stack.enter_context(TestClient(app))
        schema = schemathesis.openapi.from_asgi("/openapi.json", app)
        statuses, failures, per_op = collections.Counter(), [], collections.Counter()
        started = time.monotonic()
        for result in schema.get_all_operations():
            operation = result.ok()

            @settings(
                max_examples=args.examples,
                deadline=None,
                database=None,
                suppress_health_check=list(HealthCheck),
            )
            @given(case=operation.as_strategy())
            def exercise(case):
                response = case.call()
                per_op[case.operation.label] += 1
                statuses[response.status_code] += 1
                if breach := error_contract_breach(case.operation.label, response):
                    failures.append(breach)

            exercise()
    report = {
        "store": "postgresql" if args.postgres else "sqlite",
        "requests": sum(statuses.values()),
        "operations": len(per_op),
        "seconds": round(time.monotonic() - started, 1),
        "statuses": {str(k): v for k, v in sorted(statuses.items())},
        "failures": len(failures),
        "first_failures": failures[:10],
    }
    print(json.dumps(report, indent=2))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
