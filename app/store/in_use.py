"""Which processes have a SQLite store open: API processes and workers hold a shared lock
on a file beside the store for as long as they run, and a restore takes it exclusively.

A restore under a running service would leave it acting on rows that no longer exist or
now mean something else (a worker finishing job 12 of the old store marks job 12 of the
restored one; a cached model version 6 is not the restored store's version 6), so it is
refused while any process holds the lock. The kernel drops a process's lock when it dies,
however it dies, so a killed process never blocks a restore. A service starting during a
restore waits for it and then opens the restored store.
PostgreSQL stores are not restored by this service, so nothing is locked for them.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy.engine import make_url

try:
    import fcntl
except ImportError:  # not on Windows: there the store is not guarded
    fcntl = None  # type: ignore[assignment]

log = logging.getLogger(__name__)


class StoreInUseError(RuntimeError):
    """A running API process or worker has the store open."""


def lock_path(url: str) -> Path | None:
    """The lock file of a SQLite store file, or None where there is nothing to guard."""
    parsed = make_url(url)
    if (
        fcntl is None
        or parsed.get_backend_name() != "sqlite"
        or parsed.database in (None, "", ":memory:")
    ):
        return None
    store = Path(parsed.database)
    return store.with_name(store.name + ".in-use")


@contextmanager
def opened_by_service(url: str) -> Iterator[None]:
    """Hold the store open for a running API process or worker (a shared lock)."""
    with _locked(url) as fd:
        if fd is not None and not _try(fd, fcntl.LOCK_SH):
            log.warning("the store is being restored; waiting for the restore to finish")
            fcntl.flock(fd, fcntl.LOCK_SH)
        yield


@contextmanager
def closed_to_service(url: str) -> Iterator[None]:
    """The store to oneself (an exclusive lock), or StoreInUseError at once."""
    with _locked(url) as fd:
        if fd is not None and not _try(fd, fcntl.LOCK_EX):
            raise StoreInUseError(
                f"the store {make_url(url).database} is in use by a running API process or worker: "
                "stop every 'tactile-zsl serve' and 'tactile-zsl worker' on it first"
            )
        yield


@contextmanager
def _locked(url: str) -> Iterator[int | None]:
    path = lock_path(url)
    if path is None:
        yield None
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        yield fd
    finally:
        os.close(fd)  # closing the file drops its lock


def _try(fd: int, mode: int) -> bool:
    try:
        fcntl.flock(fd, mode | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
