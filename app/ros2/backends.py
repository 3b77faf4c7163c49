"""Who answers the bridge: a running service over HTTP (``ServiceBackend``), or a model
bundle file in this process (``ModelFileBackend``, as ``tactile-zsl recognize --lines``).

Both give the JSON bodies ``POST /v1/recognize`` gives: the answer, or the RFC 9457
problem with which the service refuses the same input (the model file's answers build it
with the service's own code, ``app.api.problems``). Neither raises for bad input or a
service that is down: every call returns a body.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.api.problems import Problem, blame, framework_problem, problem_body
from app.framework import bundle
from app.framework.defaults import DEFAULT_KNOWN_KEPT
from app.framework.errors import FrameworkError
from app.framework.results import ABSTAIN, check_outliers
from app.framework.some_procedures import TARGET_CONFIDENCE

RECOGNIZE, CLASSES = "/v1/recognize", "/v1/classes"


@dataclass
class ModelInfo:
    """What the bridge needs of the served model (``GET /v1/models/active``)."""

    version: int | None
    input_shape: tuple[int, ...]
    input_kind: str
    procedures: tuple[str, ...] = ()


@dataclass
class Health:
    """A probe's outcome, for ``/diagnostics``."""

    reachable: bool
    message: str
    model: ModelInfo | None = None
    warning: str | None = None
    values: dict[str, str] = field(default_factory=dict)


def internal_problem(instance: str) -> dict[str, Any]:
    return problem_body(500, "internal error in the bridge; its log has the details", instance)


class ServiceBackend:
    """A service at ``url``. After a failure to reach it, inputs are answered at once with a
    503 problem until a retry is due: ``backoff`` seconds, doubling on each failure up to
    ``max_backoff``; the first success resets it."""

    def __init__(
        self,
        url: str,
        api_key: str | None = None,
        timeout: float = 10.0,
        backoff: float = 0.5,
        max_backoff: float = 30.0,
        enrol_wait: float = 600.0,
    ) -> None:
        from app.client import TactileClient

        if backoff <= 0 or max_backoff < backoff or enrol_wait <= 0:
            raise ValueError("backoff must be > 0, max_backoff ≥ backoff and enrol_wait > 0")
        self.url = url
        self.client = TactileClient(url, api_key=api_key, timeout=timeout, retries=0)
        self.backoff, self.max_backoff, self.enrol_wait = backoff, max_backoff, enrol_wait
        self.model: ModelInfo | None = None
        self._failures = 0
        self._retry_at = 0.0
        self._last_error = ""
        self._lock = threading.Lock()  # answers, enrolments and probes come from three threads

    @property
    def source(self) -> str:
        return self.url

    def recognize(
        self,
        samples: np.ndarray,
        target_confidence: float | None = None,
        known_kept: float | None = None,
        objects: list[Any] | None = None,
    ) -> dict[str, Any]:
        """``target_confidence``, ``known_kept``: the request's (None: the service's);
        ``objects``: a table's labels, one per sample (named jointly, docs/TABLES.md)."""
        return self._call(
            RECOGNIZE,
            lambda: self.client.recognize(
                samples,
                target_confidence=target_confidence,
                known_kept=known_kept,
                objects=objects,
            ),
        )

    def recognize_trial(
        self, trial: dict[str, Any], known_kept: float | None = None
    ) -> dict[str, Any]:
        wire = {**trial, "fingers": [_lists(f) for f in trial["fingers"]]}
        params = {} if known_kept is None else {"known_kept": known_kept}

        def send() -> dict[str, Any]:
            # the client's recognize_trials takes no known_kept; the route does
            return self.client._send(
                "POST", RECOGNIZE, json={"trials": [wire]}, params=params
            ).json()

        return self._call(RECOGNIZE, send)

    def enrol(self, body: dict[str, Any]) -> dict[str, Any]:
        """The enrolment's job once it succeeded or failed (its class live, or why not), or
        the problem with which the service refused it."""

        def enrol() -> dict[str, Any]:
            job = self.client.create_class(body)["job"]
            deadline = time.monotonic() + self.enrol_wait
            while job["status"] not in ("succeeded", "failed"):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                job = self.client.job(job["id"], wait=min(20.0, left))
            return job

        return self._call(CLASSES, enrol)

    def probe(self) -> Health:
        """Whether the service answers, and its active model (``GET /v1/models/active``)."""
        started = time.perf_counter()
        active = self._call("/v1/models/active", self.client.active_model)
        if "detail" in active:  # a problem
            return Health(False, active["detail"], self.model)
        self.model = ModelInfo(
            active.get("version"),
            tuple(active.get("input_shape") or ()),
            active.get("input_kind", "samples"),
            tuple(active.get("procedures") or ()),
        )
        took = f"{(time.perf_counter() - started) * 1e3:.1f}"
        return Health(True, "service reachable", self.model, values={"probe_ms": took})

    def close(self) -> None:
        self.client.close()

    def _call(self, instance: str, request) -> dict[str, Any]:
        from app.client import ServiceError, ServiceUnreachable

        with self._lock:
            waiting = self._retry_at - time.monotonic()
        if waiting > 0:
            return self._unreachable(instance, f"retrying in {waiting:.1f} s")
        try:
            out = request()
        except ServiceUnreachable as exc:
            with self._lock:
                self._failures += 1
                delay = min(self.max_backoff, self.backoff * 2 ** (self._failures - 1))
                self._retry_at = time.monotonic() + delay
                self._last_error = str(exc).split(": ", 1)[-1]
            return exc.problem or self._unreachable(instance, f"retrying in {delay:.1f} s")
        except ServiceError as exc:
            self._reached()
            return exc.problem or problem_body(exc.status or 502, str(exc), instance)
        self._reached()
        out.pop("source", None)  # the client's own field: the bridge relays the body as sent
        return out

    def _reached(self) -> None:
        with self._lock:
            self._failures, self._retry_at = 0, 0.0

    def _unreachable(self, instance: str, when: str) -> dict[str, Any]:
        detail = f"the service at {self.url} cannot be reached ({self._last_error}); {when}"
        return problem_body(503, detail, instance)


class ModelFileBackend:
    """A model bundle file answering in this process, read again whenever it changes (a
    sync renames a new one over it); ``<file>.json`` beside it (written by
    ``TactileClient.sync_model``) names its version and class ids when it describes this
    very file. A changed file that cannot be read leaves the model read before answering,
    with a warning in the diagnostics. ``outliers``: what an input outlier's answer is, as
    the service's ``TACTILE_OUTLIERS``: ``"abstain"`` (no class: ``kind``
    ``"input_outlier"``) or ``"answer"`` (the model's guess, flagged). ``known_kept``: the
    novelty operating point, as the service's ``TACTILE_KNOWN_KEPT`` (the same default; a
    model without a calibration curve answers at its own threshold)."""

    def __init__(
        self,
        path: str | Path,
        top_k: int = 3,
        outliers: str = ABSTAIN,
        known_kept: float | None = DEFAULT_KNOWN_KEPT,
    ) -> None:
        if top_k < 1:
            raise ValueError(f"top_k must be at least 1, got {top_k}")
        self.path = Path(path)
        self.top_k = top_k
        self.outliers = check_outliers(outliers)
        if known_kept is not None and not 0.0 < known_kept < 1.0:
            raise ValueError(f"known_kept must lie in (0, 1), got {known_kept}")
        self.known_kept = known_kept
        self._file = bundle.BundleFile(self.path)
        self._file.load()  # a model that cannot be read is the caller's error, at once
        self._meta: dict[str, Any] = self._read_meta()
        self._warning: str | None = None
        self._lock = threading.Lock()

    @property
    def source(self) -> str:
        return str(self.path)

    @property
    def model(self) -> ModelInfo:
        rec = self._file.model
        return ModelInfo(self._meta.get("version"), rec.input_shape, rec.input_kind, rec.procedures)

    def recognize(
        self,
        samples: np.ndarray,
        target_confidence: float | None = None,
        known_kept: float | None = None,
        objects: list[Any] | None = None,
    ) -> dict[str, Any]:
        """``target_confidence``, ``known_kept``: this answer's (None: the backend's);
        ``objects``: a table's labels, one per sample, named as the service names them."""
        from app.api.routes.recognize import Body, takes_kind

        target = TARGET_CONFIDENCE if target_confidence is None else target_confidence
        kept = self.known_kept if known_kept is None else known_kept
        if objects is not None:
            return self._table(samples, objects, target_confidence, kept)

        def run(rec: Any) -> Any:
            takes_kind(rec, Body(samples, None, 1))
            with blame("samples"):
                return rec.recognize_batch(
                    samples,
                    self.top_k,
                    target_confidence=target,
                    known_kept=rec.operating_point(None, kept),
                )

        return self._answered(run)

    def _table(
        self, samples: np.ndarray, objects: list[Any], target: float | None, kept: float | None
    ) -> dict[str, Any]:
        """A table named from the model file, as ``POST /v1/recognize`` names it."""
        from app.api.routes.recognize import Body, takes_kind
        from app.service.table_answers import LabelError, table_body

        with self._lock:
            rec = self._current()
            try:
                takes_kind(rec, Body(samples, None, 1))
                with blame("samples"):
                    return table_body(
                        rec,
                        self._meta,
                        objects,
                        samples,
                        self.top_k,
                        target,
                        rec.operating_point(None, kept),
                        self.outliers,
                    )
            except LabelError as exc:
                field = [{"field": exc.field, "reason": str(exc)}]
                return problem_body(422, str(exc), RECOGNIZE, field)
            except Problem as exc:
                return problem_body(exc.status_code, str(exc.detail), RECOGNIZE, exc.errors)
            except FrameworkError as exc:
                return framework_problem(exc, RECOGNIZE)

    def recognize_trial(
        self, trial: dict[str, Any], known_kept: float | None = None
    ) -> dict[str, Any]:
        from app.api import trials

        kept = self.known_kept if known_kept is None else known_kept

        def run(rec: Any) -> Any:
            parsed = trials.one(trial, "trials", 0)
            with blame("trials"):
                return rec.recognize_trials([parsed], self.top_k, rec.operating_point(None, kept))

        return self._answered(run)

    def _answered(self, run: Callable[[Any], Any]) -> dict[str, Any]:
        """``run(model)``'s answer as HTTP's body, or the problem HTTP would give."""
        with self._lock:
            rec = self._current()
            try:
                batch = run(rec)
            except Problem as exc:
                return problem_body(exc.status_code, str(exc.detail), RECOGNIZE, exc.errors)
            except FrameworkError as exc:
                return framework_problem(exc, RECOGNIZE)
            return self._answer(batch)

    def enrol(self, body: dict[str, Any]) -> dict[str, Any]:
        detail = (
            "enrolment needs the service: this bridge answers from a model file (--model); "
            "start it with --url to enrol"
        )
        return problem_body(503, detail, CLASSES)

    def probe(self) -> Health:
        with self._lock:
            self._current()
            return Health(True, "model file loaded", self.model, self._warning)

    def close(self) -> None:
        pass

    def _current(self):
        try:
            rec, fresh = self._file.load()
            if fresh:  # a readable file replaced the one that was not
                self._meta, self._warning = self._read_meta(), None
            return rec
        except (ValueError, OSError) as exc:  # BundleError is a ValueError
            if self._file.model is None:
                raise
            self._warning = (
                f"{self.path} changed and cannot be read ({exc}); answering with "
                "the model read before"
            )
            return self._file.model

    def _answer(self, batch: Any) -> dict[str, Any]:
        return {
            "model_version": self._meta.get("version"),
            "results": batch.records(self._meta.get("class_ids", {}), self.outliers),
        }

    def _read_meta(self) -> dict[str, Any]:
        try:
            meta = json.loads(self.path.with_name(self.path.name + ".json").read_text())
        except (OSError, ValueError):
            return {}
        return meta if isinstance(meta, dict) and meta.get("sha256") == self._file.sha256 else {}


def _lists(finger: dict[str, Any]) -> dict[str, Any]:
    return {k: np.asarray(v).tolist() for k, v in finger.items()}


def backend_of(settings: dict[str, Any]) -> ServiceBackend | ModelFileBackend:
    """The backend the node's parameters name: ``url`` (with ``api_key``, ``timeout``) or
    ``model`` (with ``top_k``); ValueError naming the parameter otherwise."""
    url, model = settings.get("url") or "", settings.get("model") or ""
    if bool(url) == bool(model):
        raise ValueError(
            "give the service's URL or a model file, one of them: --url or --model "
            "(the parameters url and model: --ros-args -p url:=http://host:8000)"
        )
    if settings.get("api_key") and model:
        raise ValueError("--api-key (the parameter api_key) goes with --url, not --model")
    if float(settings.get("timeout", 10.0)) <= 0 or int(settings.get("top_k", 3)) < 1:
        raise ValueError("--timeout (timeout) must be > 0 and --top-k (top_k) at least 1")
    if model:
        from app.framework.runtime import configure_threads

        configure_threads()  # as tactile-zsl recognize: one thread unless told otherwise
        return ModelFileBackend(model, top_k=int(settings.get("top_k", 3)))
    return ServiceBackend(
        url, api_key=settings.get("api_key") or None, timeout=float(settings.get("timeout", 10.0))
    )
