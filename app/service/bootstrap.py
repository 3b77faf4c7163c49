"""First start: migrate the store and, when it holds no model, train the base model.

The base model's classes and *all* its training samples go into the store, so a
later full retrain (promotion) can be made from the store alone. A lease keeps
two processes starting at once from both training.

A service started without a dataset (``--dataset none``, ``TACTILE_DATASET=none``) has no
classes, no attributes and no model: attributes are added through the API, classes are
registered with their samples, and the worker trains the first model once
``FIRST_MODEL_CLASSES`` classes have ``FIRST_MODEL_SAMPLES`` samples each
(``first_model_missing`` says what is missing until then).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.data.biotac import BioTacDataset
from app.data.dataset import TactileDataset
from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.recognizer import RAW_TRIALS, TactileRecognizer
from app.framework.registry import make_method
from app.store import bundles, leases, migrate, repo
from app.store.enums import ClassKind, Origin, VersionReason
from app.store.models import ModelVersion
from app.store.vocabulary import vector_key

LEASE = "bootstrap"
#: the dataset spec of a service that starts empty
NO_DATASET = "none"
#: the first model of a service started empty: this many classes with this many live samples
#: each (method ``best`` fits on two classes of two trials; each enrolled sample is a trial)
FIRST_MODEL_CLASSES = 2
FIRST_MODEL_SAMPLES = 2
Dataset = TactileDataset | BioTacDataset
Trainer = Callable[[], tuple[TactileRecognizer, Dataset]]


def say(msg: str) -> None:
    print(f"tactile-zsl: {msg}", file=sys.stderr, flush=True)


def train_base(settings: Settings, progress: bool = True) -> tuple[TactileRecognizer, Dataset]:
    from app.data.sources import open_dataset  # heavy; only a bootstrap needs it

    # raw trials stay raw: the model fits its featurizer on them and keeps it
    dataset = open_dataset(settings.dataset)
    if settings.base_model is not None:
        return trained_model(settings.base_model, dataset, settings.dataset), dataset
    what = "raw trials" if isinstance(dataset, BioTacDataset) else "samples"
    say(
        f"training the base model ({settings.method}) on '{settings.dataset}': "
        f"{len(dataset)} {what} of {dataset.n_classes} objects; this runs once"
    )
    model = make_method(settings.method, **settings.params_for()).fit(dataset, progress=progress)
    return model, dataset


def trained_model(path: Path, dataset: Dataset, spec: str) -> TactileRecognizer:
    """The bundle at ``path``, checked against the bootstrap ``dataset`` it must have been
    trained on (a BundleError naming the first difference)."""
    model = bundle.load(path)
    reg = model.registry
    for what, theirs, ours in (
        ("known classes", reg.known_names, list(dataset.class_names)),
        ("attributes", list(reg.attribute_names), list(dataset.attribute_names)),
    ):
        if theirs != ours:
            at = next(
                (i for i, (a, b) in enumerate(zip(theirs, ours, strict=False)) if a != b), None
            )
            where = f"at position {at}" if at is not None else f"{len(theirs)} against {len(ours)}"
            raise BundleError(
                f"model bundle {path} was not trained on dataset '{spec}': its {what} differ "
                f"({where})"
            )
    raw = isinstance(dataset, BioTacDataset)
    if (model.input_kind == RAW_TRIALS) != raw or (
        not raw and tuple(model.input_shape) != tuple(dataset.input_shape)
    ):
        raise BundleError(
            f"model bundle {path} takes {model.input_kind} of shape {list(model.input_shape)}; "
            f"dataset '{spec}' does not have them"
        )
    say(f"base model read from {path} ({model.method}, {len(reg.known_names)} known objects)")
    return model


def starts_empty(settings: Settings) -> bool:
    return settings.dataset.strip() == NO_DATASET


def first_model_missing(s: Session) -> str | None:
    """What a service started without a dataset still lacks for its first model (None:
    nothing; the worker trains it at its next round)."""
    counts = repo.sample_counts(s)
    ready = sum(1 for n in counts.values() if n >= FIRST_MODEL_SAMPLES)
    if ready >= FIRST_MODEL_CLASSES:
        return None
    return (
        "the service started without a dataset and has no model yet: the first one is trained "
        f"once {FIRST_MODEL_CLASSES} classes have at least {FIRST_MODEL_SAMPLES} samples each "
        f"({ready} so far); register classes with their samples (POST /v1/classes with "
        "'samples' or 'trials')"
    )


def ensure_ready(
    settings: Settings,
    engine: Engine,
    sessions: sessionmaker[Session],
    trainer: Trainer | None = None,
    progress: bool = True,
) -> int | None:
    """Migrate, bootstrap if needed; returns the active model version (None for a service
    started without a dataset that has no model yet)."""
    from app.framework.runtime import configure_threads

    configure_threads(settings.torch_threads)  # every serve and worker process starts here
    migrate.upgrade(engine)
    if starts_empty(settings):
        with sessions() as s:
            return repo.active_version_number(s)
    holder = leases.new_holder_id()
    waited = False
    while True:
        with sessions() as s:
            version = repo.active_version_number(s)
            if version is not None:
                return version
            if leases.try_acquire(s, LEASE, holder, settings.lease_seconds):
                break
        if not waited:
            say("another process is training the base model; waiting for it")
            waited = True
        time.sleep(0.5)
    try:
        with leases.Renewer(sessions, LEASE, holder, settings.lease_seconds):
            with sessions() as s:  # it may have finished between our check and the lease
                version = repo.active_version_number(s)
            if version is None:
                model, dataset = (trainer or (lambda: train_base(settings, progress)))()
                with sessions.begin() as s:
                    version = store_base_model(s, model, dataset)
                say(f"base model stored as version {version}")
            return version
    finally:
        with sessions() as s:
            leases.release(s, LEASE, holder)


def store_base_model(s: Session, model: TactileRecognizer, dataset: Dataset) -> int:
    """The dataset's vocabulary, classes and samples (raw trials as they were read), and the
    model as version 1, active."""
    repo.add_attributes(s, dataset.attribute_names)
    ids = []
    # graded values as they are, values not known as not known
    for name, vector in zip(dataset.class_names, dataset.attribute_values, strict=True):
        ids.append(repo.add_class(s, name, vector_key(vector), ClassKind.KNOWN, Origin.DATASET).id)
    row = add_model_version(s, model, bundle.split(model), VersionReason.BOOTSTRAP, None, [])
    repo.activate(s, row.version)
    if isinstance(dataset, BioTacDataset):
        samples, trials = dataset.trials, dataset.trial_ids
    else:
        samples, trials = dataset.samples, dataset.trials
    repo.add_dataset_samples(s, np.asarray(ids)[dataset.labels], samples, trials)
    return row.version


def add_model_version(
    s: Session,
    model: TactileRecognizer,
    split: bundles.Split,
    reason: str,
    base_version: int | None,
    sample_ids: list[int],
) -> ModelVersion:
    """A new, inactive version row for ``model`` (its bundle's parts ``split``, stored
    here), with what the store keeps of it: method, input, attributes, procedures,
    metrics and classes."""
    return repo.add_version(
        s,
        method=model.method,
        reason=reason,
        base_version=base_version,
        bundle_sha256=bundles.store_model(s, split),
        input_shape=list(model.input_shape),
        input_kind=model.input_kind,
        attribute_names=list(model.registry.attribute_names),
        procedures=list(model.procedures),
        first_procedure=model.first_procedure,
        metrics=repo.jsonable(model.metrics),
        classes=model_classes(model),
        sample_ids=sample_ids,
    )


def model_classes(model: TactileRecognizer) -> list[dict[str, str]]:
    reg = model.registry
    return [{"name": n, "kind": ClassKind.KNOWN} for n in reg.known_names] + [
        {"name": n, "kind": ClassKind.NOVEL} for n in reg.novel_names
    ]
