"""Reliability runs at full size against real processes (the tests run them small).

    .venv/bin/python -m bench.reliability crash --kills 50 [--postgres URL]
    .venv/bin/python -m bench.reliability concurrency --clients 100 --postgres URL
    .venv/bin/python -m bench.reliability hotswap --versions 20 [--postgres URL]
    .venv/bin/python -m bench.reliability pg-outage --faults 15
    .venv/bin/python -m bench.reliability sqlite-faults --faults 30

--postgres takes a server URL (e.g. postgresql://postgres@127.0.0.1:5432/test); the run
gets a fresh database on it, dropped afterwards. pg-outage starts a PostgreSQL server of
its own instead (app/testing/pgserver.py), since it stops and crashes it; the
service runs ``best`` there, so that POST /v1/describe answers too. Prints one JSON report.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
from pathlib import Path

from app.testing import scenarios
from app.testing.harness import Cluster
from app.testing.service import fresh_postgres_database


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "scenario", choices=["crash", "concurrency", "hotswap", "pg-outage", "sqlite-faults"]
    )
    p.add_argument("--postgres", default="", help="PostgreSQL server URL; default SQLite")
    p.add_argument("--kills", type=int, default=50)
    p.add_argument("--clients", type=int, default=100)
    p.add_argument("--versions", type=int, default=20)
    p.add_argument("--apis", type=int, default=2)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--faults", type=int, default=15, help="pg-outage / sqlite-faults: faults")
    p.add_argument("--db-timeout", type=float, default=3.0, help="TACTILE_DB_TIMEOUT_SECONDS")
    args = p.parse_args()
    if args.scenario == "pg-outage":
        return pg_outage(args)
    if args.scenario == "sqlite-faults":  # in process: the fault is made on its engine
        with tempfile.TemporaryDirectory() as tmp:
            report = scenarios.sqlite_faults(tmp, args.faults, seed=args.seed)
        report.update(scenario="sqlite-faults", store="sqlite")
        print(json.dumps(report, indent=2))
        return 0
    workers = args.workers or (2 if args.scenario == "concurrency" else 1)
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        env = {"TACTILE_PROMOTION_THRESHOLD": "1000"} if args.scenario == "crash" else {}
        cluster = Cluster(
            Path(tmp) / "data", url, n_api=args.apis, n_workers=workers, extra_env=env
        )
        try:
            if args.scenario == "crash":
                report = scenarios.crash(cluster, args.kills, args.seed)
            elif args.scenario == "concurrency":
                report = scenarios.concurrency(cluster, args.clients)
            else:
                report = scenarios.hot_swap(cluster, args.versions)
        except BaseException:
            print(cluster.logs(), file=sys.stderr)
            raise
        finally:
            cluster.stop()
    report.update(scenario=args.scenario, store="postgresql" if args.postgres else "sqlite")
    print(json.dumps(report, indent=2))
    return 0


def pg_outage(args: argparse.Namespace) -> int:
    from app.testing.pgserver import PostgresServer, missing_reason
    from app.testing.service import BEST_PARAMS

    if reason := missing_reason():
        print(f"cannot run pg-outage: {reason}", file=sys.stderr)
        return 2
    server = PostgresServer()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            server.start()
            cluster = Cluster(
                Path(tmp) / "data",
                server.url,
                n_api=args.apis,
                n_workers=args.workers or 2,
                extra_env={
                    "TACTILE_METHOD": "best",
                    "TACTILE_METHOD_PARAMS": json.dumps({"best": BEST_PARAMS}),
                    "TACTILE_DB_TIMEOUT_SECONDS": str(args.db_timeout),
                    "TACTILE_PROMOTION_THRESHOLD": "1000",
                },
            )
            try:
                report = scenarios.pg_outage(cluster, server, args.faults, args.seed)
            except BaseException:
                print(cluster.logs(), server.logs(), sep="\n", file=sys.stderr)
                raise
            finally:
                cluster.stop()
        finally:
            server.close()
    report.update(scenario="pg-outage", store="postgresql (own server)", db_timeout=args.db_timeout)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
