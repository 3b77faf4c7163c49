"""A daemon thread that calls ``refresh()`` every ``poll_seconds`` until stopped."""

from __future__ import annotations

import logging
import threading

log = logging.getLogger(__name__)


class Poller:
    """Base of objects that keep a copy of store state fresh in each API process.

    Subclasses set ``_poll`` (seconds), ``_thread_name`` and ``_failure`` (logged when
    a refresh fails; the last good copy keeps serving) and implement ``refresh``.
    """

    _thread_name = "poller"
    _failure = "refresh failed"

    def __init__(self, poll_seconds: float) -> None:
        self._poll = poll_seconds
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def refresh(self) -> object:
        raise NotImplementedError

    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self._thread_name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def _run(self) -> None:
        while not self._stop.wait(self._poll):
            try:
                self.refresh()
            except Exception:  # keep serving the last good copy; try again next tick
                log.exception(self._failure)
