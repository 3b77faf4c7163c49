"""Requests waiting for their jobs to finish (``GET /v1/jobs/{id}?wait=``), woken together.

However many robots wait, an API process asks the store one question per interval: which
of these jobs have finished. Each waiting request only holds an ``asyncio.Event``, no
database connection and no thread; the watching task runs only while someone waits.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence

from fastapi.concurrency import run_in_threadpool
from sqlalchemy.orm import Session, sessionmaker

from app.store import repo

log = logging.getLogger(__name__)

QUERY_CHUNK = 500  # job ids per IN (...) list


class JobWatch:
    def __init__(self, sessions: sessionmaker[Session], interval: float = 0.2) -> None:
        self._sessions = sessions
        self.interval = interval
        self._waiting: dict[int, set[asyncio.Event]] = {}
        self._task: asyncio.Task | None = None
        self._failing = False  # one error per outage in the log, not one per interval
        self._closing = False

    @property
    def waiting(self) -> int:
        """Requests waiting now."""
        return sum(len(events) for events in self._waiting.values())

    async def wait(self, job_id: int, timeout: float) -> bool:
        """Until job ``job_id`` has finished (True) or ``timeout`` seconds passed (False).
        Once the process shuts down, at once (True: the caller reads the status then)."""
        if self._closing:
            return True
        event = asyncio.Event()
        self._waiting.setdefault(job_id, set()).add(event)
        if self._task is None or self._task.done():
            self._task = asyncio.create_task(self._watch(), name="job-watch")
        try:
            await asyncio.wait_for(event.wait(), timeout)
            return True
        except TimeoutError:
            return False
        finally:
            events = self._waiting.get(job_id, set())
            events.discard(event)
            if not events:
                self._waiting.pop(job_id, None)

    async def _watch(self) -> None:
        while self._waiting:
            await asyncio.sleep(self.interval)
            ids = list(self._waiting)
            try:
                finished = await run_in_threadpool(self._finished, ids)
            except Exception:  # the store is unreachable: waiters time out, or it comes back
                if not self._failing:
                    log.exception(
                        "could not read the jobs that requests wait for; retrying every %.1f s",
                        self.interval,
                    )
                self._failing = True
                continue
            if self._failing:
                log.info("reading the jobs that requests wait for again")
                self._failing = False
            for job_id in finished:
                for event in self._waiting.get(job_id, ()):
                    event.set()

    def _finished(self, ids: Sequence[int]) -> set[int]:
        with self._sessions() as s:
            return {
                j
                for start in range(0, len(ids), QUERY_CHUNK)
                for j in repo.finished_job_ids(s, ids[start : start + QUERY_CHUNK])
            }

    def release_all(self) -> None:
        """The process is shutting down: every waiting request answers now, with its job's
        status then, instead of holding the shutdown for up to its whole wait."""
        self._closing = True
        for events in self._waiting.values():
            for event in events:
                event.set()

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
