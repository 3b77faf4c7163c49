"""The retraining worker: claim queued enrollments, build, activate, repeat.

One round claims *every* queued job, so enrollments that arrived while the
previous retrain ran are folded into one new version. The new version, its
activation and the jobs' success are one transaction: API processes see either
the old model or the complete new one. A round that fails leaves the active
model alone; a failed batch of several jobs is retried one job at a time so one
bad enrollment does not sink the others.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from collections.abc import Callable
from contextlib import AbstractContextManager
from datetime import UTC, datetime, timedelta

import numpy as np
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.recognizer import TactileRecognizer
from app.service.bootstrap import (
    FIRST_MODEL_SAMPLES,
    add_model_version,
    first_model_missing,
    starts_empty,
)
from app.store import bundles, leases, repo, retention
from app.store.enums import JobStatus
from worker.kept_method import record_choice, refit_method
from worker.retrain import Plan, Rebuild, build, known_dataset, make_first_plan, make_plan

log = logging.getLogger(__name__)

LEASE = "retrain"  # one retrain of the model lineage at a time


class Worker:
    """``on_activate(version, model)`` is called after each version it activates, with the
    model itself; no build modifies a model afterwards (each one copies its base)."""

    def __init__(
        self,
        settings: Settings,
        sessions: sessionmaker[Session],
        on_activate: Callable[[int, TactileRecognizer], None] | None = None,
        parts: bundles.PartCache | None = None,
        handover: Callable[[], AbstractContextManager[None]] = contextlib.nullcontext,
    ) -> None:
        self.settings = settings
        self.sessions = sessions
        self.id = leases.new_holder_id()
        self.on_activate = on_activate
        # held from the commit of a version to ``on_activate``: the embedded worker's model
        # holder then waits for it instead of loading that version from the store
        self._handover = handover
        self._cache: tuple[int, TactileRecognizer] | None = None  # last model built or loaded
        # parts of the versions loaded, by SHA-256: a version built elsewhere is loaded by
        # reading only the parts not held (an enrollment changes none of the large ones).
        # ``parts``: the cache of the process's model holder (the embedded worker's), so that
        # the model the worker loads shares the served model's arrays and the cues built
        # from them instead of holding a copy of its own (GBs at 10,000 objects)
        self._parts = parts if parts is not None else bundles.PartCache()
        # parts unchanged since the last version are not encoded again
        self._encoder = bundle.PartEncoder(freeze=True)
        # kept heads' parts, so pruning reads new heads only
        self._part_refs: dict[str, set[str]] = {}

    # ------------------------------------------------------------------ rounds
    def run_once(self) -> int:
        """One round; returns how many jobs it finished."""
        with self.sessions() as s:
            if not repo.jobs_pending(s):
                return 0
            if not leases.try_acquire(s, LEASE, self.id, self.settings.lease_seconds):
                return 0
        try:
            with leases.Renewer(self.sessions, LEASE, self.id, self.settings.lease_seconds):
                with self.sessions.begin() as s:
                    # we hold the lease, so nobody else is running anything: orphans
                    if n := repo.requeue_running(s):
                        log.warning("re-queued %d job(s) left running by a stopped worker", n)
                    # idempotency records only come with enrollments, so rounds are often enough
                    ttl = timedelta(hours=self.settings.idempotency_ttl_hours)
                    repo.purge_idempotency(s, datetime.now(UTC) - ttl)
                with self.sessions() as s:
                    if repo.active_version_number(s) is None and first_model_missing(s):
                        return 0  # started empty: the jobs wait for the first model's samples
                    jobs = repo.claim_queued_jobs(s, self.id)
                if jobs:
                    self._process([j.id for j in jobs])
                    self._prune()
                return len(jobs)
        finally:
            with self.sessions() as s:
                leases.release(s, LEASE, self.id)

    def run(self, stop: threading.Event) -> None:
        # Linux niceness is per thread: this lowers the retrains only, in the worker
        # process and in the API process's embedded worker thread alike.
        if self.settings.worker_nice and hasattr(os, "nice"):
            os.nice(self.settings.worker_nice)
        try:
            self.warm_up()
        except Exception:  # the first job loads the model anyway
            log.exception("could not load the active model ahead of the first job")
        while not stop.is_set():
            try:
                busy = self.run_once()
            except Exception:  # a database hiccup must not end the worker
                log.exception("worker round failed; retrying")
                busy = 0
            if not busy:
                stop.wait(self.settings.worker_poll_seconds)

    def warm_up(self) -> None:
        """Load the active model, and build or load its compiled kernels, before the first
        job: otherwise the first enrollment after a start took ~1 s longer than the rest."""
        with self.sessions() as s:
            base = repo.active_version(s)
            if base is None:
                return
            model = self._load(s, base.version, base.bundle_sha256)
        model.recognize(np.zeros((1, *model.input_shape), np.float32))

    def _prune(self) -> None:
        """Old versions go in batches of a tenth of those kept, since finding the
        bundle parts nobody uses reads every kept version's head (once per worker)."""
        keep = self.settings.keep_versions
        if not keep:
            return
        try:
            with self.sessions.begin() as s:
                pruned = retention.prune(s, keep, slack=keep // 10, part_refs=self._part_refs)
        except Exception:  # the versions stay until the next round; the jobs are done
            log.exception("could not prune old model versions")
            return
        if pruned:
            log.info(
                "pruned %d model versions (%d to %d), %d bundle rows (%d bytes)",
                len(pruned.versions),
                pruned.versions[0],
                pruned.versions[-1],
                pruned.bundles,
                pruned.bytes,
            )

    # -------------------------------------------------------------------- jobs
    def _process(self, job_ids: list[int]) -> None:
        try:
            self._retrain(job_ids)
        except (OperationalError, BundleError):
            # the store, not the jobs (unreachable, or the active model's stored bytes
            # damaged: `store check` names them, a rollback or restore mends it): they stay
            # claimed, and the next round (this worker's or another's, under the lease) puts
            # them back in the queue
            raise
        except Exception as exc:
            if len(job_ids) > 1:
                log.warning(
                    "retrain of %d jobs failed (%s); retrying one by one", len(job_ids), exc
                )
                for job_id in job_ids:
                    self._process([job_id])
                return
            log.exception("job %s failed", job_ids[0])
            with self.sessions.begin() as s:
                repo.finish_jobs(s, job_ids, JobStatus.FAILED, error=f"{type(exc).__name__}: {exc}")

    def _retrain(self, job_ids: list[int]) -> None:
        with self.sessions() as s:
            base = repo.active_version(s)
            jobs = repo.get_jobs(s, job_ids)
            if base is None:  # a service started empty: its first model
                model, plan = None, make_first_plan(s, jobs)
            else:
                model = self._load(s, base.version, base.bundle_sha256)
                threshold = self.settings.promotion_threshold
                keep = threshold
                if starts_empty(self.settings):
                    # every class it has learnt from samples is known, as in its first model:
                    # one enrolled later is no less an object the robot has touched (a novel
                    # class of 2 samples beside known ones was named right 0.33 of the time)
                    threshold = keep = min(threshold, FIRST_MODEL_SAMPLES)
                plan = make_plan(
                    s,
                    base,
                    model,
                    jobs,
                    threshold,
                    keep_known=keep,
                    grow_fraction=self.settings.grow_fraction,
                )
            refit = plan.rebuild in (Rebuild.FULL, Rebuild.ATTRIBUTES)
            known = known_dataset(s, plan, model.procedures if model else ()) if refit else None
            if plan.rebuild is Rebuild.FULL:
                plan.method, plan.kept_choice = refit_method(
                    self.settings,
                    model,
                    base.version if base else None,
                    known.n_classes,
                    plan.choose_method,
                )
        # the session is closed: no transaction stays open while training runs
        if plan.changes_model:
            log.info(
                "retraining v%s (%s rebuild, %s): %d new class(es), samples for %d",
                base.version if base else "-",
                plan.rebuild,
                plan.reason,
                len(plan.new_classes),
                len(plan.new_samples),
            )
            new = build(plan, model, self.settings, known)
            if plan.rebuild is Rebuild.FULL:
                new = record_choice(new, plan.kept_choice, model)
            split = self._encoder.split(new)  # serialised before the transaction opens
        ok = [j for j in job_ids if j not in plan.rejected]
        with self._handover():
            with self.sessions.begin() as s:
                for job_id, reason in plan.rejected.items():
                    repo.finish_jobs(s, [job_id], JobStatus.FAILED, error=reason)
                if not plan.changes_model:  # already in the active model (e.g. a re-run)
                    repo.finish_jobs(s, ok, JobStatus.SUCCEEDED, version=base.version)
                    return
                version = self._commit(s, base.version if base else None, new, split, plan, ok)
            self._cache = (version, new)
            # the cache holds the new version's parts as its model's own arrays: those it
            # shares with the version before are those very arrays for an enrollment (99.2 of
            # 99.4 MB for the default method at 1,000 objects), and a promotion's appended
            # arrays hold the blocks they share, so the old ones can go
            self._parts.adopt(self._encoder)
            log.info("model version %d is active", version)
            if self.on_activate:
                self.on_activate(version, new)

    def _commit(
        self,
        s: Session,
        base_version: int | None,
        new: TactileRecognizer,
        split: bundles.Split,
        plan: Plan,
        job_ids: list[int],
    ) -> int:
        row = add_model_version(s, new, split, plan.reason, base_version, plan.sample_ids)
        repo.activate(s, row.version)
        repo.finish_jobs(s, job_ids, JobStatus.SUCCEEDED, version=row.version)
        repo.promote_classes(s, [c.id for c in plan.promote])
        repo.demote_classes(s, [c.id for c in plan.demote])
        return row.version

    def _load(self, s: Session, version: int, sha256: str) -> TactileRecognizer:
        if self._cache is None or self._cache[0] != version:
            model = bundles.load_model(s, sha256, self._parts)
            # its parts are stored: the next version names those it shares instead of
            # encoding them again
            self._encoder.prime(model, repo.bundle_data(s, sha256))
            self._cache = (version, model)
        return self._cache[1]


def start_in_thread(worker: Worker) -> tuple[threading.Thread, threading.Event]:
    """The embedded worker of ``tactile-zsl serve``."""
    stop = threading.Event()
    thread = threading.Thread(target=worker.run, args=(stop,), name="retrain-worker", daemon=True)
    thread.start()
    return thread, stop
