"""What the requests of one API process share, typed: built once by ``create_app``."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.service.holder import ModelHolder
from app.service.job_watch import JobWatch
from app.service.keys import KeyRing, RateLimiter
from app.service.metrics import Metrics
from app.service.recognition import RecognitionService
from app.store.bundles import ExportCache


@dataclass
class ServiceState:
    """``app.state.service``; routes reach its parts through ``app.api.deps``."""

    settings: Settings
    sessions: sessionmaker[Session]
    local_store: bool  # SQLite: closing a session costs no network round trip
    holder: ModelHolder  # the model served now, swapped when a new version is activated
    metrics: Metrics
    job_metrics_at_scrape: bool  # read the job figures at each scrape (one process only)
    recognition: RecognitionService
    keys: KeyRing
    job_watch: JobWatch  # answers GET /v1/jobs/{id}?wait= when a job finishes
    exports: ExportCache  # model files robots download, joined once per version
    limiter: RateLimiter
