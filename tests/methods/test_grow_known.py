"""Known classes learnt without a refit (``with_known_samples``, how ``best`` promotes a
class) against a model fitted on everything: the bound the docs state is checked here."""

import io
import json
import zipfile

import numpy as np
import pytest

from app.framework import bundle
from app.framework.bundle import from_bytes, to_bytes
from app.framework.errors import BundleError, FrameworkError, UnsupportedOperationError
from app.methods.best import BestRecognizer
from app.methods.forest import FlatForest
from bench.grow_known import TRAIN_TRIALS, compare, promote, split

OBJECTS, PROMOTED = 40, 4


def _format(data: bytes) -> int:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return json.loads(zf.read("manifest.json"))["format_version"]


def _split(seed: int):
    return split(seed, OBJECTS)


@pytest.fixture(scope="module")
def fitted():
    """(dataset, train mask, base on all but the last PROMOTED objects, params) for seed 0."""
    ds, train = _split(0)
    old = np.arange(OBJECTS - PROMOTED)
    base = BestRecognizer(seed=0, n_estimators=30).fit(
        ds.subset(np.flatnonzero(train & np.isin(ds.labels, old))).select_classes(old)
    )
    return ds, train, base


def _one_new_class():
    """(x, y, mask of the older classes, a forest grown on them) of seed 1's training trials."""
    ds, train = _split(1)
    x = ds.samples.reshape(len(ds.samples), -1)[train]
    y = ds.labels[train]
    old = y < OBJECTS - 1
    return x, y, old, FlatForest.grow(x[old], y[old], OBJECTS - 1, 20, "sqrt", 0, 1)


def test_grown_forest_keeps_what_it_knew_and_learns_the_new_class():
    x, y, old, forest = _one_new_class()
    grown = forest.with_samples(x[~old], y[~old], OBJECTS, x[old], y[old], "sqrt", 0)
    # the leaves the new samples reach are grown on: its own training samples are its class
    assert (grown.predict_proba(x[~old]).argmax(axis=1) == OBJECTS - 1).all()
    # the others land where they did (their leaves only split further)
    before = forest.predict_proba(x[old]).argmax(axis=1)
    assert (grown.predict_proba(x[old]).argmax(axis=1) == before).mean() >= 0.99
    p = grown.predict_proba(x)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    assert grown.leaf_count.sum() >= forest.leaf_count.sum() + (~old).sum() * forest.n_trees
    # built without the check a stored forest gets, and it would pass it
    again = FlatForest.from_state(grown.get_state(), OBJECTS, x.shape[1])
    np.testing.assert_array_equal(again.predict_proba(x), p)
    # a forest stored before leaf counts were kept loads with one sample per leaf
    state = _before_records(forest.get_state())
    del state["leaf_count"]
    assert (FlatForest.from_state(state, OBJECTS - 1, x.shape[1]).leaf_count == 1).all()


def test_grown_leaves_hold_what_reaches_them_and_the_rest_is_copied():
    x, y, old, forest = _one_new_class()
    grown = forest.with_samples(x[~old], y[~old], OBJECTS, x[old], y[old], "sqrt", 0)
    # every leaf a training sample (seen or new) reaches: its distribution and count are
    # those samples' (a forest grown with codes counts its leaves exactly)
    reached = grown.apply(x)  # (N, trees) leaf nodes
    for t in range(grown.n_trees):
        for node in np.unique(reached[:, t]):
            labels = y[reached[:, t] == node]
            classes, n = np.unique(labels, return_counts=True)
            held, shares = grown.distribution(node)
            np.testing.assert_array_equal(held, classes)
            np.testing.assert_allclose(shares, n / n.sum(), rtol=1e-12)
            assert grown.leaf_count[grown.leaf_index(node)] == len(labels)
            # a leaf of one class answers it from its record, others from their entries
            assert (grown.nodes[node, 3] >= 0) == (len(classes) == 1)
    # a promotion only appends: the forest's own arrays start the grown one's, unchanged
    # (a store then writes only the new blocks), and reached leaves are redirected
    before, after = forest.get_state(), grown.get_state()
    for key in set(before) - {"roots"}:
        np.testing.assert_array_equal(after[key][: len(before[key])], before[key], err_msg=key)
    assert (after["redirect_to"] >= len(before["nodes"])).all()
    assert set(after["redirect_from"]) == set(np.unique(forest.apply(x[~old])))
    # a stored forest whose redirects could loop, or that redirects a split node, is refused
    for to in (after["redirect_from"], np.zeros_like(after["redirect_to"])):
        with pytest.raises(ValueError, match="redirected leaves"):
            FlatForest.from_state({**after, "redirect_to": to}, OBJECTS, x.shape[1])
    # the extended redirects are those a load makes from the stored state
    fresh = FlatForest.from_state(grown.get_state(), OBJECTS, x.shape[1])
    np.testing.assert_array_equal(grown.walk_arrays()[1], fresh.walk_arrays()[1])


def test_promotions_append_in_place_and_earlier_forests_answer_as_before():
    x, y, old, forest = _one_new_class()
    first, second = np.flatnonzero(~old)[:5], np.flatnonzero(~old)[5:]
    p0 = forest.predict_proba(x)
    grown = forest.with_samples(x[first], y[first], OBJECTS, x[old], y[old], "sqrt", 0)
    p1 = grown.predict_proba(x)
    # written behind the forest's rows (a fitted forest has room): no row was copied
    for key in ("nodes", "leaf_count", "mixed_ptr"):
        assert np.shares_memory(getattr(grown, key), getattr(forest, key)), key
    # a forest no promotion grew has no leaf to go on from: its walk looks none up, and it
    # holds no redirect buffer until a promotion grows from it (then shared, with room)
    assert forest.walk_arrays()[1].size == 0 and grown.walk_arrays()[1].size > 0
    loaded = FlatForest.from_state(forest.get_state(), OBJECTS - 1, x.shape[1])
    assert loaded.redirect_nbytes == 0
    assert forest.redirect_nbytes == grown.redirect_nbytes > 4 * len(grown.leaf_count)
    seen_x, seen_y = np.concatenate([x[old], x[first]]), np.concatenate([y[old], y[first]])
    twice = grown.with_samples(x[second], y[second], OBJECTS, seen_x, seen_y, "sqrt", 1)
    assert np.shares_memory(twice.nodes, forest.nodes)
    assert np.shares_memory(twice.walk_arrays()[1], grown.walk_arrays()[1])  # in place too
    # the forests before answer as they did: a later promotion's redirects are not theirs
    np.testing.assert_array_equal(forest.predict_proba(x), p0)
    np.testing.assert_array_equal(grown.predict_proba(x), p1)
    # a second promotion of the same forest copies, and answers as one of a forest that
    # never had room (loaded from its state) does
    sibling = forest.with_samples(x[second], y[second], OBJECTS, x[old], y[old], "sqrt", 1)
    assert not np.shares_memory(sibling.nodes, forest.nodes)
    loaded = FlatForest.from_state(forest.get_state(), OBJECTS - 1, x.shape[1])
    alone = loaded.with_samples(x[second], y[second], OBJECTS, x[old], y[old], "sqrt", 1)
    np.testing.assert_array_equal(sibling.predict_proba(x), alone.predict_proba(x))
    np.testing.assert_array_equal(sibling.walk_arrays()[1], alone.walk_arrays()[1])
    for forest_, p in ((forest, p0), (grown, p1)):
        np.testing.assert_array_equal(forest_.predict_proba(x), p)
    # and every forest's redirects are those a load makes from its stored state, but for
    # the redirects of later promotions, past its nodes, which its walk does not follow
    for forest_ in (grown, twice, sibling):
        fresh = FlatForest.from_state(forest_.get_state(), OBJECTS, x.shape[1])
        after = forest_.walk_arrays()[1].copy()
        later = after >= forest_.n_nodes
        assert later.any() == (forest_ is grown)
        after[later] = -1
        np.testing.assert_array_equal(after, fresh.walk_arrays()[1])
        np.testing.assert_array_equal(forest_.apply(x), fresh.apply(x))
        np.testing.assert_array_equal(forest_.predict_proba(x), fresh.predict_proba(x))


def test_growing_reads_only_the_seen_samples_of_the_classes_it_reaches():
    x, y, old, forest = _one_new_class()

    class Seen:  # the seen samples, counting the rows read
        read: list = []

        def __len__(self):
            return int(old.sum())

        def __getitem__(self, rows):
            Seen.read.extend(np.asarray(rows).tolist())
            return x[old][rows]

    partial = forest.with_samples(x[~old], y[~old], OBJECTS, Seen(), y[old], "sqrt", 0)
    whole = forest.with_samples(x[~old], y[~old], OBJECTS, x[old], y[old], "sqrt", 0)
    for key, value in whole.get_state().items():
        np.testing.assert_array_equal(partial.get_state()[key], value, err_msg=key)
    reached = np.unique(forest.apply(x[~old]))
    held = {int(c) for n in reached for c in forest.distribution(n)[0]}
    assert {int(c) for c in y[old][Seen.read]} == held  # those classes' samples, no others
    assert len(Seen.read) < old.sum()


def test_promotion_without_a_refit_stays_near_a_full_fit():
    """Over 3 seeds, 4 promotions into a 36-object model against a fit on all 40: held-out
    accuracy within 0.05 of the full fit's, and on the promoted objects' 24 held-out trials
    within 0.3 (``python -m bench.grow_known``, docs/BENCHMARKS.md; the splits above the
    grown leaves were chosen without them)."""
    report = compare(seeds=3, objects=OBJECTS, promoted=PROMOTED, trees=50)
    for r in report["seeds"]:
        assert r["same_classes"] and r["grown_samples"] == PROMOTED * TRAIN_TRIALS
    mean = report["mean"]
    assert mean["grown_all"] >= mean["full_all"] - 0.05
    assert mean["grown_promoted"] >= mean["full_promoted"] - 0.3


def test_a_grown_model_round_trips_and_keeps_its_novel_classes(fitted):
    ds, train, base = fitted
    novel_name = ds.class_names[-1]
    with_novel = base.add_novel_classes([novel_name], ds.class_attributes[-1:])
    with_novel = with_novel.add_one_shot(novel_name, ds.samples[ds.labels == OBJECTS - 1][:2])
    promoted = OBJECTS - PROMOTED
    grown = promote(with_novel, ds, train, [promoted])
    assert grown.registry.novel_names == [novel_name]
    assert grown.registry.known_names[-1] == ds.class_names[promoted]
    assert grown.shot_prototypes_.shape == (1, OBJECTS - PROMOTED + 1)
    again = from_bytes(to_bytes(grown))
    # a forest's bundle is format 4 (its nodes as records): a build that reads only 1 to 3
    # refuses it instead of failing to find the forest's node arrays
    assert _format(to_bytes(grown)) == _format(to_bytes(with_novel))
    assert _format(to_bytes(grown)) == bundle.RECORDS_FORMAT_VERSION
    with pytest.MonkeyPatch.context() as m:
        m.setattr(bundle, "READS", bundle.READS[:-1])
        with pytest.raises(BundleError, match="format version 4"):
            from_bytes(to_bytes(grown))
    x = ds.samples[~train]
    a, b = grown.recognize_batch(x), again.recognize_batch(x)
    np.testing.assert_array_equal(a.top_index, b.top_index)
    np.testing.assert_array_equal(a.novelty_score, b.novelty_score)


def _before_records(state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A forest's state as bundles held it before the records: five node arrays, and a
    class distribution for every leaf (``leaf_ptr``, ``leaf_class``, ``leaf_value``)."""
    nodes, ptr = state["nodes"], state["mixed_ptr"]
    leaf = nodes[:, 0] < 0
    by_ordinal = np.flatnonzero(leaf)[np.argsort(nodes[leaf, 2])]
    classes, values = [], []
    for answer in nodes[by_ordinal, 3]:
        if answer >= 0:
            classes.append([answer])
            values.append([1.0])
        else:
            at = slice(ptr[-1 - answer], ptr[-answer])
            classes.append(state["mixed_class"][at])
            values.append(state["mixed_value"][at])
    out = {k: v for k, v in state.items() if k != "nodes" and not k.startswith("mixed_")}
    return {
        **out,
        "feature": nodes[:, 0].copy(),
        "threshold": nodes[:, 1].view(np.float32).astype(np.float64),
        "left": np.where(leaf, -1, nodes[:, 2]),
        "right": np.where(leaf, -1, nodes[:, 3]),
        "leaf_of_node": np.where(leaf, nodes[:, 2], -1),
        "leaf_ptr": np.r_[0, np.cumsum([len(c) for c in classes])].astype(np.int64),
        "leaf_class": np.concatenate(classes).astype(np.int32),
        "leaf_value": np.concatenate(values).astype(np.float64),
    }


def test_a_bundle_from_before_the_records_loads_and_answers_the_same(fitted):
    """Bundles written before 2026-11-26 held each forest as five node arrays and a class
    distribution for every leaf (format 3 for a grown one); they load into the same
    records and the same answers."""
    ds, train, base = fitted
    c = OBJECTS - PROMOTED
    grown = promote(base, ds, train, [c])
    manifest, arrays = bundle._contents(grown)
    forests = {name.removesuffix("nodes") for name in arrays if name.endswith("forest/nodes")}
    old = {k: v for k, v in arrays.items() if not k.startswith(tuple(forests))}
    for prefix in forests:
        state = {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)}
        old.update({prefix + k: v for k, v in _before_records(state).items()})
    assert len(forests) > 1 and len(old) > len(arrays)
    loaded = from_bytes(bundle._zip({**manifest, "format_version": 3}, old))
    x = ds.samples[~train]
    a, b = grown.recognize_batch(x), loaded.recognize_batch(x)
    np.testing.assert_array_equal(a.top_index, b.top_index)
    np.testing.assert_array_equal(a.novelty_score, b.novelty_score)
    for m in (grown, loaded):
        assert m.known_.cues_model.forest.redirect_from.size > 0
    np.testing.assert_array_equal(
        loaded.known_.cues_model.forest.nodes, grown.known_.cues_model.forest.nodes
    )


def test_a_novel_class_is_promoted_with_its_enrolled_description(fitted):
    ds, train, base = fitted
    c = OBJECTS - PROMOTED
    name = ds.class_names[c]
    novel = base.add_novel_classes([name], ds.class_attributes[c : c + 1])
    grown = novel.with_known_samples({name: ds.samples[train & (ds.labels == c)]})
    assert grown.registry.novel_names == [] and grown.registry.known_names[-1] == name
    np.testing.assert_array_equal(grown.registry.known_attributes[-1], ds.class_attributes[c])
    # a known class gains samples; its description cannot be changed so
    more = grown.with_known_samples({name: ds.samples[~train & (ds.labels == c)]})
    assert more.metrics["n_grown_samples"] == TRAIN_TRIALS + 2
    with pytest.raises(FrameworkError, match="known already"):
        grown.with_known_samples({name: ds.samples[:1]}, {name: ds.class_attributes[c]})
    with pytest.raises(FrameworkError, match="at least one class"):
        grown.with_known_samples({})


def test_an_index_learns_the_promoted_samples():
    ds, train = _split(2)
    old = np.arange(OBJECTS - 1)
    base = BestRecognizer(seed=0, n_estimators=10, approximate_above=100).fit(
        ds.subset(np.flatnonzero(train & np.isin(ds.labels, old))).select_classes(old)
    )
    assert base.known_.cues_model.distances.index is not None
    c = OBJECTS - 1
    x = ds.samples[train & (ds.labels == c)]
    grown = base.with_known_samples(
        {ds.class_names[c]: x}, {ds.class_names[c]: ds.class_attributes[c]}
    )
    cues = grown.known_.cues_model
    index = cues.distances.index  # the same graph, the promoted samples its exact tail
    assert index.index is base.known_.cues_model.distances.index.index
    assert index.index.ntotal + len(index.tail) == len(cues.reference) and len(index.tail) == len(x)
    z = cues.scaled(x.reshape(len(x), -1)) * cues.weights
    near = cues.distances.nearest(z, cues.reference_labels, np.full(len(x), c))
    np.testing.assert_allclose(near[:, 1:], 0.0, atol=1e-3)  # each finds itself, in its class


def test_methods_that_cannot_grow_say_so():
    from app.framework.registry import make_method
    from app.testing.service import QUICK_PARAMS, quick_dataset

    ds = quick_dataset()
    paper = make_method("paper", **QUICK_PARAMS).fit(ds)
    with pytest.raises(UnsupportedOperationError, match="fit it again"):
        paper.with_known_samples({"x": ds.samples[:2]})


def test_a_load_checks_only_the_records_appended_to_records_checked_before():
    """A promoted version that another process built extends the records that process
    checked when it loaded the version before: only the appended ones are read, and bad
    ones among them are still refused."""
    from app.framework.growing import appended
    from app.methods import forest as forest_module

    x, y, old, forest = _one_new_class()  # checked when grown: its records are known valid
    bounds = (len(forest.leaf_count), len(forest.mixed_ptr) - 1, OBJECTS - 1, x.shape[1])
    assert forest_module._checked.rows(forest.nodes, bounds) == forest.n_nodes
    grown = forest.with_samples(x[~old], y[~old], OBJECTS, x[old], y[old], "sqrt", 0)
    state = grown.get_state()
    bigger = (len(grown.leaf_count), len(grown.mixed_ptr) - 1, OBJECTS, x.shape[1])
    assert forest_module._checked.rows(state["nodes"], bigger) == forest.n_nodes
    loaded = FlatForest.from_state(state, OBJECTS, x.shape[1])
    assert forest_module._checked.rows(loaded.nodes, bigger) == grown.n_nodes
    # against other inputs (features) nothing counts as checked
    assert forest_module._checked.rows(state["nodes"], (*bigger[:3], x.shape[1] + 1)) == 0
    # a bad record appended behind checked ones is found: a copy of the first root,
    # whose children come before it there
    records = appended(loaded.nodes, loaded.nodes[forest.roots[:1]])
    assert np.shares_memory(records, loaded.nodes)
    assert forest_module._checked.rows(records, bigger) == grown.n_nodes
    with pytest.raises(ValueError, match="after their parent"):
        FlatForest.from_state({**state, "nodes": records}, OBJECTS, x.shape[1])
