"""Repository functions and the database's own guarantees (unique vectors, one active version)."""

from __future__ import annotations

import contextlib
import logging
import sqlite3
import time
from collections.abc import Iterator

import numpy as np
import pytest
from sqlalchemy import delete, event, func, literal_column, select, update
from sqlalchemy.exc import IntegrityError, OperationalError

from app.framework.errors import BundleError
from app.store import db, leases, repo
from app.store.enums import ClassKind, JobKind, JobStatus, Origin
from app.store.migrate import upgrade
from app.store.models import Bundle, Job, ModelVersion
from app.store.vocabulary import Vocabulary, describes, key_values, vector_key


def test_sample_round_trip_is_exact():
    x = np.random.default_rng(0).normal(size=(32, 30)).astype(np.float32)
    data, shape = repo.encode_sample(x)
    assert shape == [32, 30] and len(data) == x.nbytes
    assert np.array_equal(repo.decode_sample(data, shape), x)


def test_vector_key_round_trip():
    v = np.array([0, 1, 1, 0, 1], np.float32)
    assert vector_key(v) == "0,1,1,0,1"
    vocab = Vocabulary(names=("a", "b", "c", "d", "e"))
    assert np.array_equal(vocab.vector("0,1,1,0,1"), v)


def test_keys_hold_graded_and_unknown_values_and_keep_their_meaning_as_attributes_grow():
    assert vector_key([1, None, 0.5, np.nan, 0.123456, None]) == "1,,0.5,,0.1235"
    assert key_values("1,,0.5", 5) == [1.0, None, 0.5, None, None]
    vocab = Vocabulary(names=("hard", "soft", "warm"), retired=frozenset({"soft"}))
    assert vocab.active == ("hard", "warm")
    key = vocab.key({"hard": 1.0})
    assert key == "1"
    np.testing.assert_array_equal(vocab.vector(key), [1.0, np.nan])
    assert vocab.values(vocab.key({"warm": 0.25}, base=key)) == {"hard": 1.0, "warm": 0.25}
    assert vocab.without("1,0,1", "hard") == ",0,1"
    assert vocab.key_of_vector([np.nan, 0.5]) == ",,0.5"
    assert not describes(vocab, vocab.key({"hard": 0.0})) and describes(vocab, key)


def test_a_key_longer_than_the_vocabulary_read_keeps_its_newer_values():
    # a worker planned on the vocabulary it read; a class registered since carries the
    # value of an attribute added in between: its known attributes are read, the newer
    # position left alone (and kept when the key is rewritten)
    read = Vocabulary(names=("hard", "soft"))
    newer_key = "1,0,0.5"  # "hard", "soft", then an attribute the read vocabulary lacks
    assert read.values(newer_key) == {"hard": 1.0, "soft": 0.0}
    np.testing.assert_array_equal(read.vector(newer_key), [1.0, 0.0])
    assert describes(read, newer_key)
    assert read.key({"soft": 1.0}, base=newer_key) == "1,1,0.5"


def test_jsonable_makes_strict_json():
    out = repo.jsonable(
        {"a": np.float32(1.5), "b": float("nan"), "c": np.arange(2), "d": (np.inf,)}
    )
    assert out == {"a": 1.5, "b": None, "c": [0, 1], "d": [None]}


def test_bundles_are_content_addressed(store):
    _, sessions = store
    with sessions.begin() as s:
        a = repo.store_bundle(s, b"same bytes")
        b = repo.store_bundle(s, b"same bytes")
        assert a == b and len(a) == 64
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(Bundle).where(Bundle.sha256 == a)) == 1
        assert repo.bundle_data(s, a) == b"same bytes"


@contextlib.contextmanager
def statements(engine) -> Iterator[list[str]]:
    """The SQL statements ``engine`` sends while the block runs."""
    sent: list[str] = []

    def note(conn, cursor, statement, parameters, context, executemany):
        sent.append(statement)

    event.listen(engine, "before_cursor_execute", note)
    try:
        yield sent
    finally:
        event.remove(engine, "before_cursor_execute", note)


def test_bundles_of_any_size_read_back_exactly_with_one_statement(store):
    """One statement per bundle, whatever its size (a statement per 256 kB slice cost the
    square of the size on SQLite); sizes around PostgreSQL's row slices, several MB, and
    the empty bundle come back byte for byte."""
    engine, sessions = store
    rng = np.random.default_rng(0)
    n = repo.BUNDLE_READ_BYTES
    sizes = [0, 1, n - 1, n, n + 1, 3 * n + 12345, 6 * 2**20 + 7]
    with sessions.begin() as s:
        stored = [(data, repo.store_bundle(s, data)) for data in map(rng.bytes, sizes)]
    with sessions() as s:
        s.connection()  # checked out (and pinged) before anything is counted
        for data, sha in stored:
            with statements(engine) as sent:
                assert repo.bundle_data(s, sha) == data
            assert len(sent) == 1, (len(data), sent)
        with statements(engine) as sent:
            assert repo.bundle_data(s, "0" * 64) is None
        assert len(sent) == 1


def test_a_sqlite_bundle_replaced_between_lookup_and_read_is_read_by_its_hash(tmp_path):
    """SQLite finds a bundle's row, then reads its bytes by row id; a row written between
    the two (here: the bundle deleted and another stored, which takes its row id) must not
    read as a damaged bundle."""
    engine = db.make_engine(f"sqlite:///{tmp_path / 'store.db'}")
    Bundle.__table__.create(engine)
    sessions = db.make_sessionmaker(engine)
    with sessions.begin() as s:
        gone = repo.store_bundle(s, b"read while it was deleted" * 1000)
        rowid = s.scalar(select(literal_column("rowid")).where(Bundle.sha256 == gone))
    taken = []

    def meanwhile(conn, cursor, statement, parameters, context, executemany):
        if "rowid" in statement and not taken:
            with sessions.begin() as other:
                other.execute(delete(Bundle).where(Bundle.sha256 == gone))
                taken.append(repo.store_bundle(other, b"stored meanwhile" * 1000))

    event.listen(engine, "after_cursor_execute", meanwhile)
    with sessions() as s:
        assert repo.bundle_data(s, gone) is None
    event.remove(engine, "after_cursor_execute", meanwhile)
    with sessions() as s:
        assert s.scalar(select(literal_column("rowid")).where(Bundle.sha256 == taken[0])) == rowid
        assert repo.bundle_data(s, taken[0]) == b"stored meanwhile" * 1000
    engine.dispose()


def test_a_damaged_bundle_is_an_error_that_says_so(store):
    _, sessions = store
    with sessions.begin() as s:
        sha = repo.store_bundle(s, b"x" * 1000)
        s.execute(update(Bundle).where(Bundle.sha256 == sha).values(data=b"y" * 1000))
    with sessions() as s, pytest.raises(BundleError, match="damaged"):
        repo.bundle_data(s, sha)


def test_only_one_version_is_ever_active(store):
    _, sessions = store
    with sessions.begin() as s:
        v1 = repo.active_version(s)
        v2 = repo.add_version(
            s,
            method=v1.method,
            reason="update",
            base_version=1,
            bundle_sha256=v1.bundle_sha256,
            input_shape=v1.input_shape,
            metrics={},
            classes=v1.classes,
            sample_ids=[],
        )
        repo.activate(s, v2.version)
    with sessions() as s:
        assert repo.active_version_number(s) == v2.version
        assert (
            s.scalar(select(func.count()).select_from(ModelVersion).where(ModelVersion.active)) == 1
        )
    with sessions() as s, pytest.raises(IntegrityError):  # the database refuses a second one
        s.get(ModelVersion, 1).active = True
        s.commit()


def test_enrolled_classes_cannot_share_a_vector(store):
    """The unique index catches what a check-then-insert race would let through."""
    _, sessions = store
    with sessions.begin() as s:
        repo.add_class(s, "one", "1100000000000000000")
    with sessions() as s, pytest.raises(IntegrityError):
        repo.add_class(s, "two", "1100000000000000000")
        s.commit()


def test_dataset_classes_may_share_a_vector(store):
    _, sessions = store
    with sessions.begin() as s:
        repo.add_class(s, "d1", "0000000000000000011", "known", "dataset")
        repo.add_class(s, "d2", "0000000000000000011", "known", "dataset")


def test_claim_marks_every_queued_job_running(store):
    _, sessions = store
    with sessions.begin() as s:
        ids = [repo.add_job(s, "register_class", 1).id for _ in range(3)]
    with sessions() as s:
        claimed = repo.claim_queued_jobs(s, "w1")
    assert [j.id for j in claimed] == ids
    assert all(j.status == "running" and j.claimed_by == "w1" and j.started_at for j in claimed)
    with sessions() as s:
        assert repo.claim_queued_jobs(s, "w2") == []


def test_requeue_running(store):
    _, sessions = store
    with sessions.begin() as s:
        job = repo.add_job(s, "register_class", 1)
    with sessions() as s:
        repo.claim_queued_jobs(s, "dead-worker")
    with sessions.begin() as s:
        assert repo.requeue_running(s) == 1
    with sessions() as s:
        row = s.get(Job, job.id)
        assert row.status == "queued" and row.claimed_by is None and row.started_at is None


def test_lease_is_exclusive_until_released_or_expired(store):
    _, sessions = store
    with sessions() as s:
        assert leases.try_acquire(s, "x", "host-a:1:a", ttl=30)
        assert leases.try_acquire(s, "x", "host-a:1:a", ttl=30)  # re-entrant for its holder
        assert not leases.try_acquire(s, "x", "host-b:2:b", ttl=30)
        leases.release(s, "x", "host-a:1:a")
        assert leases.try_acquire(s, "x", "host-b:2:b", ttl=0.05)
    time.sleep(0.1)
    with sessions() as s:
        assert leases.try_acquire(s, "x", "host-c:3:c", ttl=30)  # expired: taken over


def test_lease_of_a_dead_local_process_is_taken_at_once(store):
    import subprocess
    import sys

    _, sessions = store
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()  # its pid is now free: the holder is dead
    dead = f"{leases.HOST}:{proc.pid}:0000"
    with sessions() as s:
        assert leases.try_acquire(s, "y", dead, ttl=300)
        assert leases.try_acquire(s, "y", leases.new_holder_id(), ttl=300)


def test_renewer_keeps_a_lease_alive(store):
    _, sessions = store
    me = leases.new_holder_id()
    with sessions() as s:
        assert leases.try_acquire(s, "z", me, ttl=0.3)
    with leases.Renewer(sessions, "z", me, ttl=0.3):
        time.sleep(0.6)
        with sessions() as s:
            assert not leases.try_acquire(s, "z", "other:1:x", ttl=1)


def test_a_renewal_the_database_refuses_is_logged_by_its_reason_alone(tmp_path, caplog):
    """A renewal that finds SQLite locked by another writer (a bootstrap storing a large
    dataset) warns with the driver's reason, not the statement, and the renewer goes on."""
    engine = db.make_engine(f"sqlite:///{tmp_path / 'store.db'}", timeout=0.05)
    upgrade(engine)
    sessions = db.make_sessionmaker(engine)
    with sessions() as s:
        assert leases.try_acquire(s, "z", "me:1:x", ttl=0.3)
    writer = sqlite3.connect(tmp_path / "store.db", isolation_level=None)
    writer.execute("BEGIN IMMEDIATE")  # another writer holds the database
    try:
        with caplog.at_level(logging.WARNING, "app.store.leases"):
            with leases.Renewer(sessions, "z", "me:1:x", ttl=0.3):
                time.sleep(0.35)
    finally:
        writer.execute("ROLLBACK")
        writer.close()
    refused = [r.getMessage() for r in caplog.records if "could not renew" in r.getMessage()]
    assert refused and refused[0] == (
        "could not renew lease z (database is locked); trying again in 0.1 s"
    )
    assert "UPDATE" not in refused[0]
    engine.dispose()


def test_version_summaries_count_classes_without_reading_them(six_versions):
    with six_versions() as s:
        full = {v.version: len(v.classes) for v in repo.list_versions(s)}
    with six_versions() as s:  # a fresh session: nothing loaded before
        summaries = repo.list_versions(s, after=2, limit=3, summary=True)
        assert [v.version for v in summaries] == [3, 4, 5]
        assert all(
            "classes" not in v.__dict__ and "sample_ids" not in v.__dict__ for v in summaries
        )
        assert [v.class_count for v in summaries] == [full[3], full[4], full[5]]
        assert full[5] == full[1] + 4


def test_what_a_retrain_reads_of_the_jobs(store):
    """The queries the worker plans a retrain with: pending jobs, each class's latest
    registration, and the samples added by succeeded or claimed jobs."""
    _, sessions = store
    x = np.zeros((2, 3), np.float32)
    with sessions.begin() as s:
        assert not repo.jobs_pending(s)
        mug, cup = repo.add_class(s, "mug", "10"), repo.add_class(s, "cup", "01")
        first = repo.add_job(s, JobKind.REGISTER_CLASS, mug.id)
        repo.finish_jobs(s, [first.id], JobStatus.FAILED)
        again = repo.add_job(s, JobKind.REGISTER_CLASS, mug.id)
        cup_reg = repo.add_job(s, JobKind.REGISTER_CLASS, cup.id)
        samples = [repo.add_sample(s, mug.id, x) for _ in range(3)]
        added = [repo.add_job(s, JobKind.ADD_SAMPLE, mug.id, r.id) for r in samples]
        repo.finish_jobs(s, [added[0].id], JobStatus.SUCCEEDED, version=2)
        repo.withdraw_sample(s, samples[1])
        ids = mug.id, cup.id, again.id, cup_reg.id, [r.id for r in samples], [j.id for j in added]
    mug_id, cup_id, again_id, cup_reg_id, sample_ids, added_ids = ids
    with sessions() as s:
        assert repo.jobs_pending(s)
        assert [j.id for j in repo.get_jobs(s, {added_ids[1], again_id})] == [
            again_id,
            added_ids[1],
        ]
        latest = {(r.id, r.class_id, r.status) for r in repo.latest_registrations(s)}
        assert latest == {(again_id, mug_id, "queued"), (cup_reg_id, cup_id, "queued")}
        rows = repo.sample_enrolments(s, {added_ids[1]})  # the third job is neither
        assert sorted(
            (r.job_id, r.class_id, r.sample_id, r.withdrawn_at is None) for r in rows
        ) == [
            (added_ids[0], mug_id, sample_ids[0], True),
            (added_ids[1], mug_id, sample_ids[1], False),
        ]
        assert [r.id for r in repo.samples_by_id(s, set(sample_ids[1:]))] == sample_ids[1:]
        assert repo.class_names_of_samples(s, sample_ids[:1]) == {"mug"}
        assert repo.class_names_of_samples(s, []) == set()


def test_class_states_are_the_live_classes_columns_a_retrain_reads(store):
    _, sessions = store
    with sessions.begin() as s:
        mug = repo.add_class(s, "mug", "10").id
        cup = repo.add_class(s, "cup", "01", kind=ClassKind.KNOWN, origin=Origin.DATASET).id
        gone = repo.add_class(s, "gone", "11").id
        repo.withdraw_class(s, repo.get_class(s, gone))
    with sessions() as s:
        states = repo.class_states(s)
        assert [tuple(r) for r in states[-2:]] == [
            (mug, "mug", ClassKind.NOVEL, Origin.ENROLLED, "10"),
            (cup, "cup", ClassKind.KNOWN, Origin.DATASET, "01"),
        ]
        columns = ("id", "name", "kind", "origin", "attribute_key")
        assert [tuple(r) for r in states] == [
            tuple(getattr(c, k) for k in columns) for c in repo.list_classes(s)
        ]
        assert gone not in {r.id for r in states}
        assert states[-1].kind == ClassKind.KNOWN and states[-2].attribute_key == "10"


def test_promotion_and_demotion(store):
    _, sessions = store
    with sessions.begin() as s:
        cid = repo.add_class(s, "mug", "10").id
        repo.promote_classes(s, [cid])
        repo.promote_classes(s, [])  # nothing to do
    with sessions.begin() as s:
        cls = repo.get_class(s, cid)
        assert cls.kind == ClassKind.KNOWN and cls.promoted_at is not None
        repo.demote_classes(s, [cid])
    with sessions() as s:
        cls = repo.get_class(s, cid)
        assert cls.kind == ClassKind.NOVEL and cls.promoted_at is None


def test_ping_answers_while_the_store_does(store):
    _, sessions = store
    with sessions() as s:
        db.ping(s)
    engine = db.make_engine("postgresql://nobody@127.0.0.1:1/none", timeout=1)  # nothing listens
    with db.make_sessionmaker(engine)() as s, pytest.raises(OperationalError):
        db.ping(s)
    engine.dispose()
