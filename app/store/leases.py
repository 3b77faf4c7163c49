"""Named leases in the database: a lock that expires unless its holder renews it.

Used for the bootstrap (two processes starting on an empty store must not both
train a base model) and for retraining (one retrain of the model lineage at a
time). A lease whose holder is a dead process on this host is taken at once;
one held elsewhere is taken only after it expires.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import uuid
from datetime import timedelta

from sqlalchemy import delete, or_, select, update
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session, sessionmaker

from app.store.models import Lease, utcnow

log = logging.getLogger(__name__)

HOST = socket.gethostname()


def new_holder_id() -> str:
    return f"{HOST}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def try_acquire(session: Session, name: str, holder: str, ttl: float) -> bool:
    """Take the lease if it is free, expired, ours, or held by a dead local process."""
    now = utcnow()
    expires = now + timedelta(seconds=ttl)
    takeable = [Lease.expires_at < now, Lease.holder == holder]
    current = session.scalar(select(Lease.holder).where(Lease.name == name))
    if current is not None and _dead_local(current):
        takeable.append(Lease.holder == current)
    res = session.execute(
        update(Lease)
        .where(Lease.name == name, or_(*takeable))
        .values(holder=holder, expires_at=expires)
    )
    if res.rowcount == 1:
        session.commit()
        return True
    if current is not None:
        session.rollback()
        return False
    try:
        session.add(Lease(name=name, holder=holder, expires_at=expires))
        session.commit()
        return True
    except IntegrityError:  # someone else inserted it first
        session.rollback()
        return False


def renew(session: Session, name: str, holder: str, ttl: float) -> bool:
    res = session.execute(
        update(Lease)
        .where(Lease.name == name, Lease.holder == holder)
        .values(expires_at=utcnow() + timedelta(seconds=ttl))
    )
    session.commit()
    return res.rowcount == 1


def release(session: Session, name: str, holder: str) -> None:
    session.execute(delete(Lease).where(Lease.name == name, Lease.holder == holder))
    session.commit()


def _dead_local(holder: str) -> bool:
    host, _, rest = holder.partition(":")
    pid = rest.partition(":")[0]
    if host != HOST or not pid.isdigit():
        return False
    if int(pid) == os.getpid():
        return False  # our own process: another thread's lease is alive
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


class Renewer:
    """Keeps a held lease alive from a background thread while long work runs."""

    def __init__(self, sessions: sessionmaker[Session], name: str, holder: str, ttl: float):
        self._args = (name, holder, ttl)
        self._sessions = sessions
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"lease-{name}", daemon=True)

    def __enter__(self) -> Renewer:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        name, holder, ttl = self._args
        while not self._stop.wait(ttl / 3):
            try:
                with self._sessions() as s:
                    if not renew(s, name, holder, ttl):
                        log.warning("lease %s was taken over while %s held it", name, holder)
            except OperationalError as exc:  # a busy database must not kill the renewer
                # the driver's reason alone ("database is locked" while a bootstrap writes
                # a large dataset), not the statement and its parameters
                log.warning(
                    "could not renew lease %s (%s); trying again in %g s",
                    name,
                    exc.orig if exc.orig is not None else exc,
                    ttl / 3,
                )
