"""Retention of model versions: the newest, the active and the bootstrap version stay and
load; older ones go with the bundle rows only they used, and nothing a kept one uses."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import func, select, update

from app.framework import bundle
from app.framework.errors import BundleError
from app.service.bootstrap import model_classes
from app.store import bundles, repo, retention
from app.store.models import Bundle, ModelVersion
from app.testing.service import unused_vectors
from tests.store.conftest import SMALL_PARTS


def used_bundles(s) -> set[str]:
    heads = set(s.scalars(select(ModelVersion.bundle_sha256)))
    return heads.union(*(bundle.part_shas(repo.bundle_data(s, h)) for h in heads))


def test_old_versions_go_with_the_bundle_rows_only_they_used(six_versions):
    sessions = six_versions
    with sessions() as s:
        before = s.scalar(select(func.count()).select_from(Bundle))
        size_before = s.scalar(select(func.sum(Bundle.size)))
    with sessions.begin() as s:
        pruned = retention.prune(s, keep=2)
    assert pruned.versions == [2, 3, 4]
    with sessions() as s:
        assert [v.version for v in repo.list_versions(s)] == [1, 5, 6]
        stored = set(s.scalars(select(Bundle.sha256)))
        assert stored == used_bundles(s)  # nothing unused left, nothing used gone
        assert pruned.bundles == before - len(stored) > 3  # three heads and their own parts
        assert pruned.bytes == size_before - s.scalar(select(func.sum(Bundle.size)))
        for version, names in (
            (1, []),
            (5, ["c0", "c1", "c2", "c3"]),
            (6, [f"c{i}" for i in range(5)]),
        ):
            model = bundles.load_model(s, repo.get_version(s, version).bundle_sha256)
            assert model.registry.novel_names == names


def test_the_active_version_stays_after_a_rollback(six_versions):
    sessions = six_versions
    with sessions.begin() as s:
        assert repo.activate(s, 3)
        assert retention.prunable(s, keep=2) == [2, 4]
        assert retention.prune(s, keep=2).versions == [2, 4]
    with sessions() as s:
        assert repo.active_version_number(s) == 3
        assert bundles.load_model(s, repo.get_version(s, 3).bundle_sha256).registry.novel_names == [
            "c0",
            "c1",
        ]


def test_nothing_goes_within_the_keep_or_the_slack(six_versions):
    sessions = six_versions
    with sessions.begin() as s:
        assert not retention.prune(s, keep=5)  # 6 versions, the bootstrap one always kept
        assert not retention.prune(s, keep=2, slack=3)
        assert s.scalar(select(func.count()).select_from(ModelVersion)) == 6
    with pytest.raises(ValueError, match="keep must be at least 1"):
        with sessions() as s:
            retention.prune(s, keep=0)


def test_a_kept_version_with_a_damaged_bundle_stops_pruning(six_versions):
    """Its parts are unknown, so which rows are unused is unknown: nothing is deleted."""
    sessions = six_versions
    with sessions.begin() as s:
        s.execute(
            update(Bundle)
            .where(Bundle.sha256 == repo.get_version(s, 5).bundle_sha256)
            .values(data=b"damaged")
        )
    with sessions() as s:
        rows = s.scalar(select(func.count()).select_from(Bundle))
    with pytest.raises(BundleError, match="damaged"):
        with sessions.begin() as s:
            retention.prune(s, keep=2)
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(ModelVersion)) == 6
        assert s.scalar(select(func.count()).select_from(Bundle)) == rows


def test_activating_a_version_that_is_gone_activates_nothing(six_versions):
    sessions = six_versions
    with sessions.begin() as s:
        retention.prune(s, keep=2)
    with sessions() as s:
        assert repo.activate(s, 3) is False  # the caller rolls back
        s.rollback()
        assert repo.active_version_number(s) == 6


def test_remembered_heads_give_the_same_result(six_versions, base_model):
    """The worker keeps each head's parts between prunes; a later prune with that memory
    deletes exactly the rows a prune without it would."""
    sessions = six_versions
    model, dataset = base_model
    refs: dict[str, set[str]] = {}
    with sessions.begin() as s:
        assert retention.prune(s, keep=4, part_refs=refs).versions == [2]
        assert set(refs) == set(s.scalars(select(ModelVersion.bundle_sha256)))
        newer = model.add_novel_classes(["x"], np.asarray(unused_vectors(dataset, 1), np.float32))
        row = repo.add_version(
            s,
            method=newer.method,
            reason="update",
            base_version=6,
            bundle_sha256=bundles.store_model(s, bundle.split(newer, SMALL_PARTS)),
            input_shape=list(newer.input_shape),
            metrics={},
            classes=model_classes(newer),
        )
        repo.activate(s, row.version)
        assert retention.prune(s, keep=2, part_refs=refs).versions == [3, 4, 5]
        assert set(s.scalars(select(Bundle.sha256))) == used_bundles(s)
        assert set(refs) == set(
            s.scalars(select(ModelVersion.bundle_sha256))
        )  # forgets pruned heads
