"""Real processes under faults and load, in CI sizes (the bench/ scripts run them big):
SIGKILLs lose no 202'd enrollment, withdrawal nor new description, 100 concurrent robots
on 2 APIs + 2 workers, and zero failed recognitions while 20 versions go live."""

from __future__ import annotations

import json

import pytest

from app.testing import scenarios
from app.testing.harness import KEEP_VERSIONS, Cluster
from app.testing.service import BEST_PARAMS, fresh_postgres_database
from tests.service_fixtures import postgres_url

pytestmark = pytest.mark.slow

PG_URL = postgres_url()
needs_pg = pytest.mark.skipif(
    not PG_URL, reason="no PostgreSQL reachable (TACTILE_TEST_POSTGRES_URL or the local server)"
)

CI_KILLS = 6
CI_VERSIONS = 10  # bench/reliability.py hotswap runs 20


def assert_nothing_lost(report: dict) -> None:
    assert report["integrity_problems"] == [], report
    assert report["classes_missing"] == [] and report["samples_missing"] == [], report
    assert report["classes_not_in_model"] == [] and report["samples_not_in_model"] == [], report
    assert report.get("withdrawn_in_model", []) == report.get("withdrawn_still_live", []) == [], (
        report
    )
    assert (
        report.get("descriptions_not_stored", []) == report.get("descriptions_not_served", []) == []
    ), report
    for lost in ("attributes_not_stored", "attributes_not_served"):
        assert report.get(lost, []) == [], report
    for lost in ("values_not_stored", "values_not_served"):
        assert report.get(lost, []) == [], report
    assert set(report["jobs"]) <= {"succeeded", "failed"}, report  # none left queued
    assert report["unexpected_failures"] == [], report


def run_crash(tmp_path, database_url: str = "") -> None:
    cluster = Cluster(
        tmp_path / "crash",
        database_url,
        n_api=2,
        n_workers=1,
        extra_env={"TACTILE_PROMOTION_THRESHOLD": "1000"},
    )
    try:
        report = scenarios.crash(cluster, kills=CI_KILLS, seed=1, gap=(1.0, 3.0))
    except BaseException:
        print(cluster.logs())
        raise
    finally:
        cluster.stop()
    print(report)
    assert sum(report["kills"].values()) == CI_KILLS
    assert report["classes_202"] > 0 and report["withdrawn_202"] > 0 and report["described_202"] > 0
    assert report["attributes_202"] > 0 and report["values_202"] > 0
    assert_nothing_lost(report)


def test_crash_safety_sqlite(tmp_path):
    run_crash(tmp_path)


@needs_pg
def test_crash_safety_postgres(tmp_path):
    with fresh_postgres_database(PG_URL) as url:
        run_crash(tmp_path, url)


@needs_pg
def test_100_concurrent_robots_on_2_apis_and_2_workers(tmp_path):
    with fresh_postgres_database(PG_URL) as url:
        cluster = Cluster(tmp_path / "conc", url, n_api=2, n_workers=2)
        try:
            report = scenarios.concurrency(cluster, clients=100)
        finally:
            cluster.stop()
    print(report)
    assert set(report["statuses"]) <= {"202", "409", "422"}, report
    assert report["classes_202"] == 100
    assert_nothing_lost(report)


def test_hot_swap_drops_no_recognition(tmp_path):
    url_ctx = fresh_postgres_database(PG_URL) if PG_URL else None
    url = url_ctx.__enter__() if url_ctx else ""
    cluster = Cluster(tmp_path / "swap", url, n_api=2, n_workers=1)
    try:
        report = scenarios.hot_swap(cluster, versions=CI_VERSIONS, load_threads=4)
    finally:
        cluster.stop()
        if url_ctx:
            url_ctx.__exit__(None, None, None)
    print(report)
    assert report["versions_activated"] == CI_VERSIONS
    assert report["failed"] == 0 and report["recognitions_ok"] > 0, report
    # pruned while served: the harness keeps 3 versions, plus the bootstrap one
    assert report["versions_stored"] <= KEEP_VERSIONS + 1 and report["integrity_problems"] == [], (
        report
    )


CI_OUTAGES = 3  # one of each stop mode; bench/reliability.py pg-outage runs more
DB_TIMEOUT = 3.0


def test_postgres_outage(tmp_path):
    """A throwaway PostgreSQL server stopped (fast, immediate, SIGKILL) and restarted under
    2 API processes and 2 workers: recognitions and descriptions keep being answered from
    the loaded model (with an API key read before the outage), writes get a quick 503
    problem with Retry-After, /readyz says not ready until the server is back, nothing is
    restarted, and every 202'd enrolment reaches the served model."""
    from app.testing.pgserver import PostgresServer, missing_reason

    reason = missing_reason()
    if reason:
        pytest.skip(reason)
    server = PostgresServer()
    try:
        server.start()
        cluster = Cluster(
            tmp_path / "outage",
            server.url,
            n_api=2,
            n_workers=2,
            extra_env={
                # best predicts attributes, so POST /v1/describe answers too
                "TACTILE_METHOD": "best",
                "TACTILE_METHOD_PARAMS": json.dumps({"best": BEST_PARAMS}),
                "TACTILE_DB_TIMEOUT_SECONDS": str(DB_TIMEOUT),
                "TACTILE_PROMOTION_THRESHOLD": "1000",
            },
        )
        try:
            report = scenarios.pg_outage(cluster, server, faults=CI_OUTAGES, seed=3)
        except BaseException:
            print(cluster.logs())
            print(server.logs())
            raise
        finally:
            cluster.stop()
    finally:
        server.close()
    print(report)
    assert report["read_paths"] == ["/v1/recognize", "/v1/describe"], report
    assert report["faults"] == CI_OUTAGES and set(report["modes"]) == {"fast", "immediate", "kill"}
    assert report["restarts"] == [], report
    # reads: every one answered from the loaded model, outage or not
    assert report["reads_during_outage"] > 0 and report["reads_failed"] == [], report
    # writes during the outage: 503 problem+json with Retry-After, none hanging
    assert report["writes_during_outage"] > 0 and report["writes_during_outage_bad"] == [], report
    assert set(report["write_statuses"]) <= {"202", "503"}, report
    assert report["write_seconds_max"] <= DB_TIMEOUT + 1.5, report
    # readiness follows the store, and comes back without a restart after every fault
    assert report["readyz_during_outage"] > 0, report
    assert report["readyz_ready_during_outage"] == report["readyz_not_problem"] == [], report
    assert None not in report["recovery_seconds"], report
    assert report["given_up"] == 0 and report["classes_202"] > 0, report
    assert_nothing_lost(report)
