"""Split bundles in the store: versions share their large parts, a process that holds a
part does not read it again, and a missing or damaged part is an error that says so."""

from __future__ import annotations

import io
import json
import sys
import threading
import zipfile

import numpy as np
import pytest
from sqlalchemy import delete, func, select, update

from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.registry import make_method
from app.store import bundles, repo
from app.store.models import Bundle
from app.testing.service import unused_vectors


@pytest.fixture
def two_versions(store, base_model):
    """(sessions, v1 head, v2 head, v1's split) of the base model and the base model
    with one more novel class, stored the way the worker stores them."""
    _, sessions = store
    model, dataset = base_model
    newer = model.add_novel_classes(["mug"], np.asarray(unused_vectors(dataset, 1), np.float32))
    encoder = bundle.PartEncoder()
    first = encoder.split(model)
    with sessions.begin() as s:
        v1 = bundles.store_model(s, first)
        rows = s.scalar(select(func.count()).select_from(Bundle))
        v2 = bundles.store_model(s, encoder.split(newer))
        # the enrollment changed the class registry only: one new row, the head
        assert s.scalar(select(func.count()).select_from(Bundle)) == rows + 1
    return sessions, v1, v2, first


def test_a_split_version_loads_back_whole(two_versions, base_model):
    sessions, _, v2, _ = two_versions
    model, dataset = base_model
    with sessions() as s:
        loaded = bundles.load_model(s, v2)
    assert loaded.registry.novel_names == ["mug"]
    x = dataset.samples[:6]
    np.testing.assert_allclose(loaded.known_proba(x), model.known_proba(x), atol=1e-6)


def test_parts_a_process_holds_are_not_read_again(two_versions):
    """With v1's parts cached, v2 loads although every one of them is now damaged in the
    store; without the cache the damage is found."""
    sessions, v1, v2, (_, parts) = two_versions
    cache = bundles.PartCache()
    with sessions() as s:
        bundles.load_model(s, v1, cache)
    assert len(cache) == len(parts) > 0
    with sessions.begin() as s:
        s.execute(update(Bundle).where(Bundle.sha256.in_(parts)).values(data=b"damaged"))
    with sessions() as s:
        assert bundles.load_model(s, v2, cache).registry.novel_names == ["mug"]
        with pytest.raises(BundleError, match="damaged"):
            bundles.load_model(s, v2)


def test_a_missing_part_is_an_error_that_names_it(two_versions):
    sessions, _, v2, (_, parts) = two_versions
    sha = next(iter(parts))
    with sessions.begin() as s:
        s.execute(delete(Bundle).where(Bundle.sha256 == sha))
    with sessions() as s, pytest.raises(BundleError, match=f"part {sha[:12]}.*missing"):
        bundles.load_model(s, v2, bundles.PartCache())


def test_the_cache_keeps_only_the_served_models_parts(two_versions, base_model):
    sessions, v1, _, _ = two_versions
    with sessions.begin() as s:  # a bundle written whole, as before bundles were split
        whole = repo.store_bundle(s, bundle.to_bytes(base_model[0]))
    cache = bundles.PartCache()
    with sessions() as s:
        bundles.load_model(s, v1, cache)
        assert len(cache) > 0
        bundles.load_model(s, whole, cache)
    assert len(cache) == 0


def test_exported_files_are_joined_once_per_version_and_the_oldest_leaves(
    two_versions, monkeypatch
):
    sessions, v1, v2, _ = two_versions
    joined = []
    real_join = bundle.join
    monkeypatch.setattr(bundle, "join", lambda *a, **k: joined.append(1) or real_join(*a, **k))
    cache = bundles.ExportCache(size=1)
    with sessions() as s:
        first = cache.export(s, v1)
        assert cache.export(s, v1) is first and len(joined) == 1  # a fleet's downloads: one join
        assert bundle.from_bytes(first).registry.novel_names == []
        assert bundle.from_bytes(cache.export(s, v2)).registry.novel_names == ["mug"]
        assert cache.export(s, v1) == first and len(joined) == 3  # v2 took v1's place


def test_the_reliability_check_finds_a_version_whose_parts_are_gone(store, settings):
    from app.store.integrity import check_store

    _, sessions = store
    assert check_store(settings.sqlalchemy_url) == []
    with sessions.begin() as s:
        head = repo.bundle_data(s, repo.active_version(s).bundle_sha256)
        s.execute(delete(Bundle).where(Bundle.sha256 == next(iter(bundle.part_shas(head)))))
    assert check_store(settings.sqlalchemy_url) == [
        "version 1 refers to bundle parts that are not stored"
    ]


def test_a_promotion_writes_only_the_blocks_it_appended(store, base_model, monkeypatch):
    """Large arrays are stored in row blocks. A promotion only appends rows to the forests
    and the reference samples, so its version shares all their earlier blocks with the
    version before; a process holding that version reads only the new blocks, and holds
    each array once (its blocks are views of it)."""
    monkeypatch.setattr(bundle, "BLOCK_BYTES", 2048)  # blocks of this small model's arrays
    _, sessions = store
    dataset = base_model[1]
    # distances in a principal subspace, and a neighbour graph over the reference points
    # (``approximate_above``), which the promotion keeps
    model = make_method(
        "best", n_estimators=10, seed=0, distance_components=8, approximate_above=50
    ).fit(dataset)
    vector = np.asarray(unused_vectors(dataset, 1)[0], np.float32)
    samples = dataset.samples[dataset.labels == 0][:4] * 1.1
    encoder = bundle.PartEncoder(min_bytes=1024, freeze=True)  # as the worker splits
    first = encoder.split(model)
    grown = model.with_known_samples({"mug": samples}, {"mug": vector})
    same = []
    compare = bundle._same_bytes
    monkeypatch.setattr(bundle, "_same_bytes", lambda a, b: same.append(compare(a, b)) or same[-1])
    second = encoder.split(grown)  # its earlier blocks compared with the model's, not hashed
    assert sum(same) > 0
    fresh = bundle.split(grown, min_bytes=1024)
    assert second[1] == fresh[1] and bundle.part_refs(second[0]) == bundle.part_refs(fresh[0])
    before, after = bundle.part_refs(first[0]), bundle.part_refs(second[0])
    appended = [n for n in after if n.endswith(("forest/nodes", "reference"))]
    # a head listing row blocks is format 3 or later: older builds refuse it
    assert (
        json.loads(zipfile.ZipFile(io.BytesIO(second[0])).read("manifest.json"))["format_version"]
        >= bundle.GROWN_FORMAT_VERSION
    )
    assert appended and all(isinstance(after[n], list) for n in appended)
    for name in appended:
        assert after[name][: len(before[name]) - 1] == before[name][:-1], name
    new_bytes = sum(len(b) for sha, b in second[1].items() if sha not in first[1])
    assert new_bytes < 0.2 * sum(len(b) for b in second[1].values())

    with sessions.begin() as s:
        v1, v2 = bundles.store_model(s, first), bundles.store_model(s, second)
    cache = bundles.PartCache()
    with sessions() as s:
        old = bundles.load_model(s, v1, cache)
    with sessions.begin() as s:  # v1's parts damaged: v2 must not read them again
        s.execute(update(Bundle).where(Bundle.sha256.in_(first[1])).values(data=b"damaged"))
    with sessions() as s:
        loaded = bundles.load_model(s, v2, cache)
        x = dataset.samples[:8]
        np.testing.assert_array_equal(loaded.known_proba(x), grown.known_proba(x))
        blocks = after["known/reference"]
        reference = loaded.known_.cues_model.distances.reference
        assert all(np.shares_memory(cache.get(s, sha), reference) for sha in blocks)
        # the new rows were appended behind the arrays v1's blocks were joined into
        for name in ("distances", "forest"):
            a, b = (getattr(m.known_.cues_model, name) for m in (loaded, old))
            a, b = (x.reference if name == "distances" else x.nodes for x in (a, b))
            assert np.shares_memory(a, b) and len(a) > len(b), name
    # and it derived anew only what the new rows need: the reference's projection is v1's
    # with rows appended, the graph v1's; both as a load that held nothing makes them
    cold = bundle.from_bytes(second[0], part=lambda sha: bundle.decode_part(second[1][sha]))
    new, was, fresh = (m.known_.cues_model.distances for m in (loaded, old, cold))
    assert new.index is not None and new.index.index is was.index.index
    assert fresh.index.index is not was.index.index
    for name in ("_ref", "_ref_sq", "_ref_res"):
        a, b = getattr(new, name), getattr(was, name)
        assert np.shares_memory(a, b) and len(a) > len(b), name
        np.testing.assert_array_equal(a, getattr(fresh, name), err_msg=name)
    np.testing.assert_array_equal(loaded.novelty_score(x), cold.novelty_score(x))


def test_a_worker_that_loaded_a_version_stores_the_next_without_encoding_its_parts(
    store, base_model, monkeypatch
):
    """A model loaded from the store primes the encoder (``PartEncoder.prime``): the next
    version's split names the parts it shares with it instead of encoding them again (the
    first version after a start encoded the whole model) and returns bytes only for arrays
    the load made anew; its head lists what a split from scratch lists. A promotion of the
    loaded model appends behind the arrays the store's blocks were joined into."""
    monkeypatch.setattr(bundle, "BLOCK_BYTES", 2048)
    _, sessions = store
    dataset = base_model[1]
    model = make_method("best", n_estimators=10, seed=0).fit(dataset)
    first = bundle.split(model, min_bytes=1024)
    with sessions.begin() as s:
        head = bundles.store_model(s, first)
    with sessions() as s:
        loaded = bundles.load_model(s, head, bundles.PartCache())
        encoder = bundle.PartEncoder(min_bytes=1024, freeze=True)
        encoder.prime(loaded, repo.bundle_data(s, head))
    # arrays the load made anew (a few kB: the procedure models' autoencoders, deep-copied);
    # the forests and references are the store's read-only parts
    _, arrays = bundle._contents(loaded)
    made = {n for n, a in arrays.items() if not bundle.unchangeable(a)}
    assert not any(n.endswith(("forest/nodes", "reference")) for n in made)
    again = encoder.split(loaded)
    refs = bundle.part_refs(again[0])
    assert refs == bundle.part_refs(first[0])
    named = {sha: n for n, r in refs.items() for sha in ([r] if isinstance(r, str) else r)}
    assert {named[sha] for sha in again[1]} <= made

    vector = np.asarray(unused_vectors(dataset, 1)[0], np.float32)
    grown = loaded.with_known_samples({"mug": dataset.samples[:4] * 1.1}, {"mug": vector})
    forest, before = grown.known_.cues_model.forest, loaded.known_.cues_model.forest
    assert np.shares_memory(forest.nodes, before.nodes)  # appended, not copied
    second = encoder.split(grown)
    fresh = bundle.split(grown, min_bytes=1024)
    assert bundle.part_refs(second[0]) == bundle.part_refs(fresh[0])
    assert set(fresh[1]) - set(first[1]) <= set(second[1])  # what the store lacks
    with sessions.begin() as s:
        v2 = bundles.store_model(s, second)
    with sessions() as s:
        x = dataset.samples[:8]
        stored = bundles.load_model(s, v2)
        np.testing.assert_array_equal(stored.known_proba(x), grown.known_proba(x))


def test_two_threads_load_versions_through_one_cache_at_once(store, base_model, monkeypatch):
    """The API process's model poller and its embedded worker load through one cache: a
    version each, at the same moment, again and again (promotions whose row blocks extend
    the held arrays, and enrollments that share them). Every load must give its version's
    answers, and the cache then holds parts of the versions loaded only."""
    monkeypatch.setattr(bundle, "BLOCK_BYTES", 2048)
    _, sessions = store
    dataset = base_model[1]
    model = make_method("best", n_estimators=10, seed=0).fit(dataset)
    vectors = np.asarray(unused_vectors(dataset, 4), np.float32)
    samples = dataset.samples[:4] * 1.1
    models = [model]
    for n in range(3):  # promotions, each appending rows to the one before
        models.append(models[-1].with_known_samples({f"p{n}": samples + n}, {f"p{n}": vectors[n]}))
    models.append(models[-1].add_novel_classes(["mug"], vectors[3:]))  # an enrollment
    encoder = bundle.PartEncoder(min_bytes=1024, freeze=True)
    with sessions.begin() as s:
        heads = [bundles.store_model(s, encoder.split(m)) for m in models]
    x = dataset.samples[:6]
    expected = [m.known_proba(x) for m in models]
    cache = bundles.PartCache()
    rounds = 12
    start = threading.Barrier(2)
    errors: list[BaseException] = []

    def load(order: list[int]) -> None:
        try:
            for r in range(rounds):
                start.wait(timeout=60)
                i = order[r % len(order)]
                with sessions() as s:
                    loaded = bundles.load_model(s, heads[i], cache)
                np.testing.assert_array_equal(loaded.known_proba(x), expected[i])
        except BaseException as exc:
            start.abort()
            errors.append(exc)

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads swap often, inside the cache's loops too
    try:
        threads = [
            threading.Thread(target=load, args=(order,))
            for order in ([0, 1, 2, 3, 4], [1, 3, 0, 4, 2])
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=300)
    finally:
        sys.setswitchinterval(switch)
    assert not errors, errors[0]
    assert not any(t.is_alive() for t in threads)
    with sessions() as s:  # and what the cache holds afterwards is sound
        loaded = bundles.load_model(s, heads[-1], cache)
    np.testing.assert_array_equal(loaded.known_proba(x), expected[-1])
