"""The model an API process serves, swapped atomically when a new version goes live.

Requests read ``holder.current`` once and use that snapshot to the end, so a swap
in the middle of a request changes nothing for it; the swap itself is a single
attribute assignment, which is atomic in Python. A background thread polls the
active version number (one indexed row) and loads a new bundle off the request
path, reading only the parts of its bundle this process does not hold yet.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from app.framework.recognizer import TactileRecognizer
from app.service.metrics import Metrics
from app.service.polling import Poller
from app.store import bundles, repo

log = logging.getLogger(__name__)


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
        self._current: LoadedModel | None = None
        self._load_lock = threading.Lock()  # one load at a time; readers never take it
        self._parts = bundles.PartCache()

    @property
    def current(self) -> LoadedModel | None:
        return self._current

    def refresh(self) -> bool:
        """Load the active version if it is not the one served; True when swapped."""
        with self._load_lock:
            with self._sessions() as s:
                version = repo.active_version_number(s)
                current = self._current
                if version is None or (current is not None and current.version == version):
                    return False
                row = repo.get_version(s, version)
                if row is None:  # activated and pruned since the line above; poll again
                    return False
                # parts the served model shares with the new one are not read again
                recognizer = bundles.load_model(s, row.bundle_sha256, self._parts)
                class_ids = repo.class_ids_by_name(s)
            self._swap(version, recognizer, class_ids)
        return True

    def serve(self, version: int, recognizer: TactileRecognizer) -> bool:
        """Serve a model this process has built (the embedded worker's) as ``version``
        without reading it back from the store, if that is still the active version;
        otherwise load the active one. True when swapped."""
        with self._load_lock:
            with self._sessions() as s:
                current = repo.active_version_number(s) == version
                class_ids = repo.class_ids_by_name(s) if current else {}
            if current:
                self._swap(version, recognizer, class_ids)
                self._parts.keep_only(set())  # the cached parts belong to no served model now
                return True
        return self.refresh()  # activated again meanwhile (a rollback)

    def _swap(self, version: int, recognizer: TactileRecognizer, class_ids: dict[str, int]) -> None:
        # One sample through the model before it is served: the compiled forest walk
        # is built (or read from numba's cache) now, not on the first robot's request.
        recognizer.recognize(np.zeros((1, *recognizer.input_shape), np.float32))
        self._current = LoadedModel(version, recognizer, class_ids)
        if self._metrics:
            self._metrics.active_version.set(version)
        log.info("serving model version %s", version)
