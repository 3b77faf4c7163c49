"""The model an API process serves, swapped atomically when a new version goes live.

Requests read ``holder.current`` once and use that snapshot to the end, so a swap
in the middle of a request changes nothing for it; the swap itself is a single
attribute assignment, which is atomic in Python. A background thread polls the
active version number (one indexed row) and loads a new bundle off the request
path, reading only the parts of its bundle this process does not hold yet.

A version whose bundle is damaged (its bytes no longer match their SHA-256) is never
served: a process that serves a model keeps it, and a process that starts with none
falls back to the newest intact version before the active one. Either way it logs which
version it serves and why, and ``degraded`` says so (``/readyz`` shows it); the damaged
version is tried again every ``DAMAGED_RETRY_SECONDS``, at once when another one goes live.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future
from dataclasses import dataclass

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.recognizer import TactileRecognizer
from app.service.metrics import Metrics
from app.service.polling import Poller
from app.store import bundles, repo

log = logging.getLogger(__name__)

DAMAGED_RETRY_SECONDS = 60.0
#: the longest a refresh waits for this process's worker to serve what it is committing
HANDOVER_WAIT_SECONDS = 60.0


class ModelWaitTimeout(TimeoutError):
    """A newer model version was not served within the wait a request may take; its load
    goes on (``ModelHolder.at_least``)."""

    def __init__(self, version: int, waited: float) -> None:
        super().__init__(
            f"model version {version} is still loading in this process after {waited:g} s "
            "(TACTILE_MODEL_WAIT_SECONDS); try again shortly"
        )
        self.version = version
        self.waited = waited


@dataclass(frozen=True)
class LoadedModel:
    version: int
    recognizer: TactileRecognizer
    class_ids: dict[str, int]  # class name -> store id, for API responses


class ModelHolder(Poller):
    _thread_name = "model-poll"
    _failure = "could not load the active model version"

    def __init__(
        self,
        sessions: sessionmaker[Session],
        poll_seconds: float = 0.5,
        metrics: Metrics | None = None,
    ) -> None:
        super().__init__(poll_seconds)
        self._sessions = sessions
        self._metrics = metrics
        # the refresh that ``at_least``'s callers share, run in a thread of its own
        self._shared: Future[bool] | None = None
        self._shared_guard = threading.Lock()
        self._current: LoadedModel | None = None
        self._load_lock = threading.Lock()  # one load at a time; readers never take it
        # versions this process's embedded worker is committing, then serving (``handing_over``)
        self._handing_over = 0
        self._handed = threading.Condition()
        self._parts = bundles.PartCache()
        # (version, when it failed, why): the active version whose bundle cannot be loaded
        self._damaged: tuple[int, float, str] | None = None
        self.degraded: str | None = None  # why the served version is not the active one

    @property
    def current(self) -> LoadedModel | None:
        return self._current

    @property
    def parts(self) -> bundles.PartCache:
        """The decoded parts of the served model, which an embedded worker loads through."""
        return self._parts

    @contextlib.contextmanager
    def handing_over(self) -> Iterator[None]:
        """While this process's embedded worker commits a version and then ``serve``s it:
        ``refresh`` (the poller's, a job waiter's) waits for that, up to
        ``HANDOVER_WAIT_SECONDS``, instead of loading the same version from the store
        meanwhile (7 s and a second copy of the model at 10,000 objects)."""
        with self._handed:
            self._handing_over += 1
        try:
            yield
        finally:
            with self._handed:
                self._handing_over -= 1
                self._handed.notify_all()

    def refresh(self) -> bool:
        """Load the active version if it is not the one served; True when swapped. When
        its bundle is damaged, keep the served model, or, with none yet, load the newest
        intact version before it (BundleError when there is none)."""
        with self._handed:
            self._handed.wait_for(lambda: not self._handing_over, HANDOVER_WAIT_SECONDS)
        return self._load_active()

    async def at_least(self, version: int, wait_seconds: float) -> LoadedModel | None:
        """The served model, once it is ``version`` or newer: a process serving an older
        one loads the active version now instead of at its next poll (a job's waiter, a
        recognition that names the version it needs). None when the active version is
        older than ``version`` (rolled back, or not made yet) or cannot be loaded
        (``degraded`` says why).

        Every caller waiting meanwhile shares one load, run in a thread of its own, and
        waits without holding a thread of the request pool: a fleet asking for a new
        version at once takes no slots from recognition. ModelWaitTimeout after
        ``wait_seconds`` (the service's ``model_wait_seconds``); the load goes on and
        serves the version when done."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + wait_seconds
        for _ in range(2):  # a shared load begun before this call may predate the version
            current = self._current
            if current is not None and current.version >= version:
                return current
            load, begun_now = self._shared_refresh()
            waiting = asyncio.wrap_future(load)
            waiting.add_done_callback(_retrieved)
            done, _ = await asyncio.wait({waiting}, timeout=max(0.0, deadline - loop.time()))
            if not done:
                raise ModelWaitTimeout(version, wait_seconds)
            waiting.result()  # its BundleError, if the load failed
            if begun_now:
                break
        current = self._current
        return current if current is not None and current.version >= version else None

    def _shared_refresh(self) -> tuple[Future[bool], bool]:
        """The ``refresh`` running for ``at_least``'s callers, or a new one; True when
        new (begun after this call, so it sees the active version as of now)."""
        with self._shared_guard:
            if self._shared is not None and not self._shared.done():
                return self._shared, False
            load: Future[bool] = Future()
            load.set_running_or_notify_cancel()  # a waiter that gives up cannot cancel it
            self._shared = load
        threading.Thread(
            target=self._refresh_into, args=(load,), name="model-load", daemon=True
        ).start()
        return load, True

    def _refresh_into(self, load: Future[bool]) -> None:
        try:
            load.set_result(self.refresh())
        except BaseException as exc:  # the waiters raise it
            load.set_exception(exc)

    def _load_active(self) -> bool:
        with self._load_lock:
            with self._sessions() as s:
                version = repo.active_version_number(s)
                current = self._current
                if version is None or (current is not None and current.version == version):
                    return False
                if (
                    current is not None
                    and self._damaged is not None
                    and self._damaged[0] == version
                    and time.monotonic() - self._damaged[1] < DAMAGED_RETRY_SECONDS
                ):
                    return False  # tried a moment ago; its bytes have not healed since
                row = repo.get_version(s, version)
                if row is None:  # activated and pruned since the line above; poll again
                    return False
                try:
                    # parts the served model shares with the new one are not read again
                    recognizer = bundles.load_model(s, row.bundle_sha256, self._parts)
                except BundleError as exc:
                    self._damaged = (version, time.monotonic(), str(exc))
                    if current is not None:
                        self._degrade(current.version, version, exc)
                        return False
                    served, recognizer = self._newest_intact(s, version, exc)
                    self._degrade(served, version, exc)
                    version = served
                else:
                    self._damaged = None
                    self.degraded = None
                class_ids = repo.class_ids_by_name(s)
            self._swap(version, recognizer, class_ids)
        return True

    def _newest_intact(
        self, s: Session, active: int, why: BundleError
    ) -> tuple[int, TactileRecognizer]:
        for row in reversed(repo.list_versions(s, summary=True)):
            if row.version >= active:  # newer ones were rolled back from: not wanted
                continue
            try:
                return row.version, bundles.load_model(s, row.bundle_sha256, self._parts)
            except BundleError as exc:
                log.error("model version %s cannot be loaded either: %s", row.version, exc)
        raise BundleError(
            f"the active model version {active} cannot be loaded ({why}) and no earlier "
            "version is intact: restore the store from a backup"
        )

    def _degrade(self, served: int, active: int, why: BundleError) -> None:
        self.degraded = (
            f"serving model version {served}, not the active version {active}: "
            f"version {active} cannot be loaded ({why})"
        )
        log.error("%s; `tactile-zsl store check` names the damage", self.degraded)

    def serve(self, version: int, recognizer: TactileRecognizer) -> bool:
        """Serve a model this process has built (the embedded worker's) as ``version``
        without reading it back from the store, if that is still the active version;
        otherwise load the active one. True when swapped.

        The cached parts that ``version`` shares stay cached, so the next version, built
        by another process, is loaded by reading only the parts they lack; the rest go.
        Until that load they are held beside the built model's own copies (the worker
        loaded its own base): ~100 MB for the default method at 1,000 objects."""
        with self._load_lock:
            with self._sessions() as s:
                current = repo.active_version_number(s) == version
                class_ids = repo.class_ids_by_name(s) if current else {}
                shared = self._part_shas(s, version) if current else set()
            if current:
                self._damaged = None
                self.degraded = None
                self._swap(version, recognizer, class_ids)
                self._parts.keep_only(shared)
                return True
        return self._load_active()  # activated again meanwhile (a rollback)

    @staticmethod
    def _part_shas(s: Session, version: int) -> set[str]:
        """The parts of ``version``'s bundle, from its head (kilobytes); none when the head
        cannot be read, as the served model does not need it."""
        row = repo.get_version(s, version)
        try:
            head = repo.bundle_data(s, row.bundle_sha256) if row is not None else None
            return bundle.part_shas(head) if head is not None else set()
        except BundleError:
            return set()

    def _swap(self, version: int, recognizer: TactileRecognizer, class_ids: dict[str, int]) -> None:
        # One sample through the model before it is served: the compiled forest walk
        # is built (or read from numba's cache) now, not on the first robot's request.
        recognizer.recognize(np.zeros((1, *recognizer.input_shape), np.float32))
        self._current = LoadedModel(version, recognizer, class_ids)
        if self._metrics:
            self._metrics.active_version.set(version)
        log.info("serving model version %s", version)


def _retrieved(waiting: asyncio.Future[bool]) -> None:
    """Read a shared load's outcome, so that one no waiter awaited any longer is not
    logged as an exception never retrieved."""
    if not waiting.cancelled():
        waiting.exception()
