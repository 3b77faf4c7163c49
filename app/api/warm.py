"""The first request of each kind as fast as the next: what a process loads on first use,
loaded in the background once it is ready."""

from __future__ import annotations

import logging
import threading
import time

from sqlalchemy.orm import Session, sessionmaker

from app.store import repo
from app.words.embedding import EmbeddingModelError

log = logging.getLogger(__name__)


def warm_words(sessions: sessionmaker[Session]) -> threading.Thread | None:
    """Load the sentence-embedding model that reads descriptions in words (about 4 s on
    first use, ``app.words.embedding``) in a daemon thread, with the vocabulary's names,
    which every description is compared with; None when the vocabulary is empty (nothing
    to read a text into: descriptions are refused, so nothing is loaded)."""
    with sessions() as s:
        names = list(repo.vocabulary(s).active)
    if not names:
        return None
    thread = threading.Thread(target=_load, args=(names,), name="warm-words", daemon=True)
    thread.start()
    return thread


def _load(names: list[str]) -> None:
    from app.api.deps import get_interpreter

    started = time.perf_counter()
    try:
        get_interpreter().closest("warm", names)  # the model, and the names' vectors cached
    except EmbeddingModelError as exc:  # an install without it: say so now, not at first use
        log.warning("descriptions in words cannot be read: %s", exc)
        return
    log.info("sentence-embedding model loaded in %.1f s", time.perf_counter() - started)
