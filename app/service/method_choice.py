"""Asking method ``auto`` to choose again (``worker/kept_method.py`` keeps its choice)."""

from __future__ import annotations

from sqlalchemy.orm import Session

from app.framework.defaults import AUTO
from app.store import repo
from app.store.enums import JobKind
from app.store.models import Job


class NothingToChoose(ValueError):
    """The service's method is a fixed one, not ``auto``: there is no choice to make."""


def ask_for_choice(session: Session, method: str, requested_by: str | None) -> Job:
    """Queue a ``choose_method`` job: the worker's next round fits ``auto`` anew on every
    stored sample, whatever it chose before. The caller commits."""
    if method != AUTO:
        raise NothingToChoose(
            f"the service's method is '{method}' (TACTILE_METHOD), not 'auto': it has no "
            "choice to make again; set TACTILE_METHOD=auto to let a probe choose"
        )
    return repo.add_job(session, JobKind.CHOOSE_METHOD, None, requested_by=requested_by)
