"""A process reads from the store only the bundle parts it does not hold: its model holder
and its worker keep the parts a version they built shares, and load the next version,
built by another process, by reading the others."""

from __future__ import annotations

import contextlib
import re
import threading
from collections.abc import Iterator

from sqlalchemy import event

from app.framework import bundle
from app.service.holder import ModelHolder
from app.store import repo
from app.store.db import make_engine, make_sessionmaker
from tests.service_fixtures import register
from worker import Worker

_SHA256 = re.compile(r"[0-9a-f]{64}")


@contextlib.contextmanager
def bundle_reads(engine) -> Iterator[list[str]]:
    """The SHA-256 named by each statement on the bundles table that ``engine`` sends
    while the block runs, once per statement."""
    named: list[str] = []

    def note(conn, cursor, statement, parameters, context, executemany):
        if "bundles" in statement:
            values = parameters.values() if isinstance(parameters, dict) else parameters
            named.extend(v for v in values if isinstance(v, str) and _SHA256.fullmatch(v))

    event.listen(engine, "before_cursor_execute", note)
    try:
        yield named
    finally:
        event.remove(engine, "before_cursor_execute", note)


def parts_of(sessions, version: int) -> set[str]:
    with sessions() as s:
        head = repo.bundle_data(s, repo.get_version(s, version).bundle_sha256)
    return bundle.part_shas(head)


def test_a_process_reads_only_the_parts_it_lacks_after_a_version_it_built(
    client, app, settings, dataset
):
    # this process: a holder polled by hand and its embedded worker, on an engine of their own
    engine = make_engine(settings.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    holder = ModelHolder(sessions)
    here = Worker(settings, sessions, on_activate=holder.serve)
    elsewhere = Worker(settings, app.state.service.sessions)  # another process's worker
    try:
        with bundle_reads(engine) as first:
            assert holder.refresh() and holder.current.version == 1
        register(client, dataset, "mug", 0)
        assert here.run_once() == 1 and holder.current.version == 2  # built and served here
        register(client, dataset, "cup", 1)
        assert elsewhere.run_once() == 1  # version 3
        with bundle_reads(engine) as by_holder:
            assert holder.refresh() and holder.current.version == 3
        with bundle_reads(engine) as by_worker:
            here.warm_up()  # its model, version 2, is stale: it loads version 3
        assert here._cache[0] == 3
    finally:
        engine.dispose()

    p1, p2, p3 = (parts_of(app.state.service.sessions, v) for v in (1, 2, 3))
    assert p1 and sorted(p for p in first if p in p1) == sorted(p1)  # each part read once
    held = p1 & p2  # what both read for version 1 and version 2 still uses
    assert held & p3, "version 3 shares parts with versions 1 and 2"
    for read in (by_holder, by_worker):
        assert sorted(p for p in read if p in p1 | p2 | p3) == sorted(p3 - held)


def test_an_embedded_worker_loads_the_served_version_without_reading_its_parts(settings, client):
    engine = make_engine(settings.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    holder = ModelHolder(sessions)
    worker = Worker(settings, sessions, on_activate=holder.serve, parts=holder.parts)
    try:
        assert holder.refresh()
        with bundle_reads(engine) as read:
            worker.warm_up()  # through the holder's cache: the served model's very parts
        assert worker._cache[0] == holder.current.version
    finally:
        engine.dispose()
    assert not set(read) & parts_of(sessions, holder.current.version)


def test_a_refresh_waits_for_the_version_the_embedded_worker_hands_over(settings, client, dataset):
    """Between the embedded worker's commit of a version and its serving it, the holder's
    poller (or a job's waiter) waits for that instead of loading the same version from the
    store meanwhile, which takes seconds and a second copy at 10,000 objects."""
    engine = make_engine(settings.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    holder = ModelHolder(sessions)
    seen: dict = {}

    def serve_later(version, model):  # the poller wakes between the commit and the serve
        seen["poll"] = threading.Thread(target=lambda: seen.setdefault("swapped", holder.refresh()))
        seen["poll"].start()
        seen["poll"].join(0.3)
        seen["waited"] = seen["poll"].is_alive()
        holder.serve(version, model)

    worker = Worker(
        settings,
        sessions,
        on_activate=serve_later,
        parts=holder.parts,
        handover=holder.handing_over,
    )
    try:
        assert holder.refresh()
        register(client, dataset, "mug", 0)
        with bundle_reads(engine) as read:
            assert worker.run_once() == 1
            seen["poll"].join(10)
        assert holder.current.version == 2
    finally:
        engine.dispose()
    assert seen["waited"] and seen["swapped"] is False  # it found version 2 served
    assert not set(read) & parts_of(sessions, 2) - parts_of(sessions, 1)
