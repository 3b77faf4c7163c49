"""Bootstrap: the base model, its classes and all its training samples go into the store, once."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from sqlalchemy import func, select

from app.service.bootstrap import ensure_ready
from app.store import bundles, repo
from app.store.db import make_engine, make_sessionmaker
from app.store.models import ObjectClass, Sample


def test_bootstrap_stores_model_classes_and_every_sample(store, base_model):
    _, dataset = base_model
    _, sessions = store
    with sessions() as s:
        assert repo.attribute_names(s) == list(dataset.attribute_names)
        classes = repo.list_classes(s)
        assert [c.name for c in classes] == list(dataset.class_names)
        assert {c.kind for c in classes} == {"known"} and {c.origin for c in classes} == {"dataset"}
        assert s.scalar(select(func.count()).select_from(Sample)) == len(dataset)
        rows = s.scalars(select(Sample).order_by(Sample.id)).all()
        stored = np.stack([repo.decode_sample(r.data, r.shape) for r in rows])
        assert np.array_equal(stored, dataset.samples)
        ids = {c.name: c.id for c in classes}
        assert [r.class_id for r in rows] == [ids[dataset.class_names[i]] for i in dataset.labels]
        assert [r.trial for r in rows] == dataset.trials.tolist()
        v1 = repo.active_version(s)
        assert v1.version == 1 and v1.reason == "bootstrap"
        loaded = bundles.load_model(s, v1.bundle_sha256)
        assert loaded.registry.known_names == list(dataset.class_names)


def test_second_start_does_not_train(store, settings):
    engine, sessions = store

    def trainer():  # pragma: no cover - must not run
        raise AssertionError("trained twice")

    assert ensure_ready(settings, engine, sessions, trainer=trainer) == 1


def test_two_processes_starting_at_once_bootstrap_once(settings, base_model):
    calls = []
    gate = threading.Event()

    def trainer():
        calls.append(1)
        gate.wait(1.0)  # hold the lease a while so the other one has to wait
        return base_model

    versions, errors = [], []

    def start():
        engine = make_engine(settings.sqlalchemy_url)
        try:
            versions.append(
                ensure_ready(settings, engine, make_sessionmaker(engine), trainer=trainer)
            )
        except Exception as exc:  # pragma: no cover
            errors.append(exc)
        finally:
            engine.dispose()

    threads = [threading.Thread(target=start) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == [] and versions == [1, 1] and len(calls) == 1
    engine = make_engine(settings.sqlalchemy_url)
    with make_sessionmaker(engine)() as s:
        assert s.scalar(select(func.count()).select_from(ObjectClass)) == base_model[1].n_classes
    engine.dispose()


def test_a_dataset_of_graded_and_unknown_values_is_stored_as_given(tmp_path, best_base):
    from app.testing.service import BEST_PARAMS, quick_settings

    model, dataset = best_base
    values = dataset.attribute_values.copy()
    values[0, 0], values[1, :3], values[2, 1] = 0.5, np.nan, 0.25
    graded = dataset.with_attributes(dataset.attribute_names, values)
    fitted = type(model)(**BEST_PARAMS).fit(graded)
    settings = quick_settings(tmp_path, method="best", method_params={"best": BEST_PARAMS})
    engine = make_engine(settings.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    ensure_ready(settings, engine, sessions, trainer=lambda: (fitted, graded), progress=False)
    with sessions() as s:
        vocab = repo.vocabulary(s)
        stored = np.stack([vocab.vector(c.attribute_key) for c in repo.list_classes(s)])
    np.testing.assert_array_equal(stored, values)  # NaN where not known, graded as given
    engine.dispose()


def test_first_start_from_a_trained_bundle_does_not_train(settings, base_model, tmp_path):
    """TACTILE_BASE_MODEL: the bundle becomes version 1 as it is (no fit), with the
    dataset's classes and samples."""
    from app.framework import bundle as bundle_format
    from app.service.bootstrap import train_base

    model, dataset = base_model
    path = tmp_path / "base.bundle"
    path.write_bytes(bundle_format.to_bytes(model))
    from_file = settings.model_copy(update={"base_model": path})
    read, read_dataset = train_base(from_file, progress=False)
    assert read_dataset.class_names == dataset.class_names
    x = dataset.samples[:20]
    assert np.array_equal(read.recognize_batch(x).top_index, model.recognize_batch(x).top_index)
    engine = make_engine(from_file.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    try:
        assert ensure_ready(from_file, engine, sessions, progress=False) == 1
        with sessions() as s:
            stored = bundles.load_model(s, repo.active_version(s).bundle_sha256)
            assert stored.registry.known_names == model.registry.known_names
            assert s.scalar(select(func.count()).select_from(Sample)) == len(read_dataset)
    finally:
        engine.dispose()


def test_a_bundle_of_another_dataset_is_refused_and_nothing_is_stored(settings, tmp_path):
    from app.data.simulator import simulate_dataset
    from app.framework import bundle as bundle_format
    from app.framework.errors import BundleError
    from app.framework.registry import make_method

    other = simulate_dataset(5, 3, seed=9)
    model = make_method("best", n_estimators=5, tuning_rounds=1).fit(other)
    path = tmp_path / "other.bundle"
    path.write_bytes(bundle_format.to_bytes(model))
    from_file = settings.model_copy(update={"base_model": path})
    engine = make_engine(from_file.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    try:
        with pytest.raises(BundleError, match="not trained on dataset .*known classes differ"):
            ensure_ready(from_file, engine, sessions, progress=False)
        with sessions() as s:
            assert repo.active_version_number(s) is None
            assert s.scalar(select(func.count()).select_from(ObjectClass)) == 0
    finally:
        engine.dispose()
