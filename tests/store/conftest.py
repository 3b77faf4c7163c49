"""Shared service fixtures live in tests/service_fixtures.py."""

import numpy as np
import pytest

from app.framework import bundle
from app.service.bootstrap import model_classes
from app.store import bundles, repo
from app.testing.service import unused_vectors
from tests.service_fixtures import *  # noqa: F403

SMALL_PARTS = 64  # bytes: each version's novel-class arrays become parts of their own


@pytest.fixture
def six_versions(store, base_model):
    """sessions of a store holding the bootstrap version 1 and versions 2-6, each with one
    more novel class than the one before; version 6 is active."""
    _, sessions = store
    model, dataset = base_model
    vectors = np.asarray(unused_vectors(dataset, 5), np.float32)
    with sessions.begin() as s:
        for n in range(1, 6):
            newer = model.add_novel_classes([f"c{i}" for i in range(n)], vectors[:n])
            row = repo.add_version(
                s,
                method=newer.method,
                reason="update",
                base_version=n,
                bundle_sha256=bundles.store_model(s, bundle.split(newer, SMALL_PARTS)),
                input_shape=list(newer.input_shape),
                metrics={},
                classes=model_classes(newer),
            )
            repo.activate(s, row.version)
    return sessions
