"""Prometheus metrics, one registry per app so tests can build many apps.

Under ``serve`` with several processes, prometheus_client's multiprocess mode keeps
every process's values in files (``PROMETHEUS_MULTIPROC_DIR``, set by the supervisor
before the processes start) and ``exposition`` sums them, whichever process is asked.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from datetime import datetime, timedelta
from typing import Any

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    generate_latest,
)
from prometheus_client.multiprocess import MultiProcessCollector
from sqlalchemy.orm import Session, sessionmaker

from app.service.polling import Poller
from app.store import repo
from app.store.enums import JobStatus
from app.store.models import utcnow

JOB_BUCKETS = (0.1, 0.25, 0.5, 1, 2, 3, 5, 10, 30, 60, 300, 1800)
# a job's finish time is set a moment before its transaction commits: look back this far
_LOOKBACK = timedelta(seconds=30)

LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.015, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5)


def multiprocess_mode() -> bool:
    """Whether prometheus_client takes this process for one of several sharing files (the
    supervisor of ``serve`` sets the variable; it also reads the older lower-case name)."""
    return "PROMETHEUS_MULTIPROC_DIR" in os.environ or "prometheus_multiproc_dir" in os.environ


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.requests = Counter(
            "tactile_http_requests", "HTTP requests.", ["method", "route", "status"], registry=r
        )
        self.latency = Histogram(
            "tactile_http_request_duration_seconds",
            "HTTP request latency.",
            ["method", "route"],
            buckets=LATENCY_BUCKETS,
            registry=r,
        )
        self.recognitions = Counter(
            "tactile_recognitions", "Samples recognised.", ["kind"], registry=r
        )
        self.enrollments = Counter(
            "tactile_enrollments", "Accepted enrollments.", ["kind"], registry=r
        )
        self.withdrawals = Counter(
            "tactile_withdrawals", "Withdrawn classes and samples.", ["kind"], registry=r
        )
        self.job_duration = Histogram(
            "tactile_job_duration_seconds",
            "Retrain time of finished jobs (start to end).",
            ["status"],
            buckets=JOB_BUCKETS,
            registry=r,
        )
        self.enrollment_to_live = Histogram(
            "tactile_enrollment_to_live_seconds",
            "From an enrollment's 202 to its job's end.",
            ["status"],
            buckets=JOB_BUCKETS,
            registry=r,
        )
        # read from the store: with several processes, the newest reading is the figure
        self.jobs = Gauge(
            "tactile_jobs",
            "Jobs in the store by status.",
            ["status"],
            registry=r,
            multiprocess_mode="mostrecent",
        )
        self.versions_stored = Gauge(
            "tactile_model_versions_stored",
            "Model versions in the store (TACTILE_KEEP_VERSIONS bounds them).",
            registry=r,
            multiprocess_mode="mostrecent",
        )
        self.bundle_bytes = Gauge(
            "tactile_model_bundle_bytes",
            "Bytes of model bundles in the store.",
            registry=r,
            multiprocess_mode="mostrecent",
        )
        # input health (app.service.input_monitor): a process's window is its own, and the
        # largest of the live processes' figures is the one to alert on
        self.input_outliers = Counter(
            "tactile_input_outliers",
            "Answers whose input lay outside the training data's channel ranges "
            "(input_outlier); divide its rate by tactile_recognitions_total's.",
            registry=r,
        )
        self.input_outlier_rate = Gauge(
            "tactile_input_outlier_rate",
            "Share of outliers among the last TACTILE_INPUT_WINDOW samples.",
            registry=r,
            multiprocess_mode="livemax",
        )
        self.input_drift = Gauge(
            "tactile_input_drift",
            "Per channel: |median of the last TACTILE_INPUT_WINDOW samples' channel statistic "
            "- training median| in training IQRs (the larger of level and spread).",
            ["channel"],
            registry=r,
            multiprocess_mode="livemax",
        )
        self.input_window_samples = Gauge(
            "tactile_input_window_samples",
            "Samples the input-drift window holds (at most TACTILE_INPUT_WINDOW).",
            registry=r,
            multiprocess_mode="livemax",
        )
        self.active_version = Gauge(  # with several processes, one series per process (pid)
            "tactile_active_model_version",
            "Model version this process serves.",
            registry=r,
            multiprocess_mode="liveall",
        )

        # jobs are finished by workers in any process; each API process reads them from the store
        self.jobs_seen_since: datetime = utcnow()
        self._seen: dict[int, datetime] = {}
        # (method, route, status) -> its request counter and latency histogram: ``labels()``
        # looks them up under a lock each time (~5 µs a request for the two)
        self._request_series: dict[tuple[str, str, int], tuple[Any, Any]] = {}

    def observe_request(self, method: str, route: str, status: int, seconds: float) -> None:
        """One answered HTTP request: counted by method, route template and status, and
        its latency observed by method and route."""
        key = (method, route, status)
        series = self._request_series.get(key)
        if series is None:
            series = (
                self.requests.labels(method, route, str(status)),
                self.latency.labels(method, route),
            )
            self._request_series[key] = series
        series[0].inc()
        series[1].observe(seconds)

    def forget_input_channels(self) -> None:
        """Drop the per-channel drift series of a model whose channels no longer apply.
        prometheus_client cannot drop labelled series in multiprocess mode (its files keep
        them, and ``clear()`` only warns, at each new model of each process): there a
        channel's series keeps its last value until set again or the process ends."""
        if not multiprocess_mode():
            self.input_drift.clear()

    def exposition(self) -> tuple[bytes, str]:
        """The Prometheus text and its content type: this process's figures, or those of
        every process of a multi-process ``serve``."""
        if "PROMETHEUS_MULTIPROC_DIR" not in os.environ:
            return generate_latest(self.registry), CONTENT_TYPE_LATEST
        registry = CollectorRegistry()
        MultiProcessCollector(registry)
        return generate_latest(registry), CONTENT_TYPE_LATEST

    def read_store(self, session: Session) -> None:
        """Job counts, the durations of jobs finished since the last reading and what the
        stored model versions take, from the store (workers in any process finish jobs and
        prune versions)."""
        counts = repo.jobs_by_status(session)
        for status in JobStatus:
            self.jobs.labels(status).set(counts.get(status, 0))
        versions, size = repo.stored_model_figures(session)
        self.versions_stored.set(versions)
        self.bundle_bytes.set(size)
        self.observe_finished_jobs(repo.jobs_finished_since(session, self.jobs_seen_since))

    def observe_finished_jobs(
        self, jobs: Iterable[tuple[int, str, datetime, datetime | None, datetime]]
    ) -> None:
        """(id, status, created_at, started_at, finished_at) of jobs finished since the last
        call."""
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


class JobMetricsPoller(Poller):
    """Reads the job figures every ``poll_seconds`` in one process of a multi-process
    ``serve``: read at each scrape by whichever process answers, every process would
    count each finished job once more."""

    _thread_name = "job-metrics"
    _failure = "metrics: could not read the jobs from the store"

    def __init__(
        self, metrics: Metrics, sessions: sessionmaker[Session], poll_seconds: float = 5.0
    ) -> None:
        super().__init__(poll_seconds)
        self._metrics = metrics
        self._sessions = sessions

    def refresh(self) -> None:
        with self._sessions() as s:
            self._metrics.read_store(s)
