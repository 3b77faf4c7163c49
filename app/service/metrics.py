"""Prometheus metrics, one registry per app so tests can build many apps."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime, timedelta

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

from app.store.models import utcnow

JOB_BUCKETS = (0.1, 0.25, 0.5, 1, 2, 3, 5, 10, 30, 60, 300, 1800)
# a job's finish time is set a moment before its transaction commits: look back this far
_LOOKBACK = timedelta(seconds=30)

LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.015, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5)


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.requests = Counter(
            "tactile_http_requests", "HTTP requests.", ["method", "route", "status"], registry=r
        )
        self.latency = Histogram(
            "tactile_http_request_duration_seconds", "HTTP request latency.", ["method", "route"],
            buckets=LATENCY_BUCKETS, registry=r,
        )
        self.recognitions = Counter(
            "tactile_recognitions", "Samples recognised.", ["kind"], registry=r
        )
        self.enrollments = Counter(
            "tactile_enrollments", "Accepted enrollments.", ["kind"], registry=r
        )
        self.job_duration = Histogram(
            "tactile_job_duration_seconds", "Retrain time of finished jobs (start to end).",
            ["status"], buckets=JOB_BUCKETS, registry=r,
        )
        self.enrollment_to_live = Histogram(
            "tactile_enrollment_to_live_seconds", "From an enrollment's 202 to its job's end.",
            ["status"], buckets=JOB_BUCKETS, registry=r,
        )
        self.jobs = Gauge("tactile_jobs", "Jobs in the store by status.", ["status"], registry=r)
        self.active_version = Gauge(
            "tactile_active_model_version", "Model version this process serves.", registry=r
        )

        # jobs are finished by workers in any process; each API process reads them from the store
        self.jobs_seen_since: datetime = utcnow()
        self._seen: dict[int, datetime] = {}

    def observe_finished_jobs(
        self, jobs: Iterable[tuple[int, str, datetime, datetime | None, datetime]]
    ) -> None:
        """(id, status, created_at, started_at, finished_at) of jobs finished since the last call."""
        for job_id, status, created, started, finished in jobs:
            if job_id in self._seen:
                continue
            self._seen[job_id] = finished
            self.enrollment_to_live.labels(status).observe((finished - created).total_seconds())
            if started is not None:
                self.job_duration.labels(status).observe((finished - started).total_seconds())
        horizon = utcnow() - _LOOKBACK
        self.jobs_seen_since = max(self.jobs_seen_since, horizon)
        self._seen = {k: t for k, t in self._seen.items() if t >= horizon}
