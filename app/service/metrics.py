"""Prometheus metrics, one registry per app so tests can build many apps."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

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
            "tactile_job_duration_seconds", "Time from a job's start to its end (this process's worker).",
            ["status"], buckets=(0.1, 0.25, 0.5, 1, 2, 5, 10, 30, 60, 300, 1800), registry=r,
        )
        self.jobs = Gauge("tactile_jobs", "Jobs in the store by status.", ["status"], registry=r)
        self.active_version = Gauge(
            "tactile_active_model_version", "Model version this process serves.", registry=r
        )
