"""The retraining worker: ``tactile-zsl worker``, or a thread inside ``tactile-zsl serve``."""

from __future__ import annotations

import threading

from app.config import Settings
from worker.loop import Worker, start_in_thread

__all__ = ["Worker", "run_worker", "start_in_thread"]


def run_worker(settings: Settings, stop: threading.Event | None = None) -> None:
    """Run until ``stop`` is set: migrate, bootstrap if the store is empty, then loop."""
    from app.service.bootstrap import ensure_ready
    from app.store.db import make_engine, make_sessionmaker
    from app.store.in_use import opened_by_service

    engine = make_engine(settings.sqlalchemy_url, settings.db_timeout_seconds)
    sessions = make_sessionmaker(engine)
    try:
        with opened_by_service(settings.sqlalchemy_url):  # no restore under a running worker
            ensure_ready(settings, engine, sessions)
            Worker(settings, sessions).run(stop or threading.Event())
    finally:
        engine.dispose()
