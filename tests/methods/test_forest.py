"""FlatForest: the same probabilities and leaves as scikit-learn, plain arrays only, checked
state."""

from __future__ import annotations

import io

import numpy as np
import pytest
from sklearn.ensemble import ExtraTreesClassifier, RandomForestClassifier

from app.methods.forest import FlatForest


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 7)).astype(np.float32)
    y = (x[:, 0] + 0.5 * x[:, 1] > 0).astype(int) + 2 * (x[:, 2] > 0.3)
    x[:10] = x[10:20]  # duplicated inputs with other labels leave impure leaves
    return x, y


@pytest.mark.parametrize("cls", [ExtraTreesClassifier, RandomForestClassifier])
def test_matches_sklearn(data, cls):
    x, y = data
    model = cls(n_estimators=25, random_state=0).fit(x, y)
    flat = FlatForest.from_sklearn(model)
    q = np.random.default_rng(1).normal(size=(50, 7)).astype(np.float32)
    np.testing.assert_allclose(flat.predict_proba(q), model.predict_proba(q), atol=1e-12)
    np.testing.assert_allclose(flat.predict_proba(x), model.predict_proba(x), atol=1e-12)
    assert np.array_equal(flat.apply(q) - flat.roots[None, :], model.apply(q))
    assert flat.n_trees == 25
    # both kinds of leaf answered: one class from the record, a mixed one from its entries
    answers = flat.nodes[flat.nodes[:, 0] < 0, 3]
    assert (answers >= 0).any() and (answers < 0).any()


@pytest.mark.parametrize("rows", [1, 3, 7])
def test_a_few_samples_walk_blocks_of_trees_to_the_same_bits(data, rows):
    # fewer samples than a block take blocks of trees down instead; 25 trees leave a
    # partial block of trees
    x, y = data
    flat = FlatForest.from_sklearn(ExtraTreesClassifier(n_estimators=25, random_state=0).fit(x, y))
    q = np.random.default_rng(2).normal(size=(40, 7)).astype(np.float32)
    every = flat.predict_proba(q)
    few = np.concatenate([flat.predict_proba(q[i : i + rows]) for i in range(0, 40, rows)])
    assert np.array_equal(few, every)
    leaves = np.concatenate([flat.apply(q[i : i + rows]) for i in range(0, 40, rows)])
    assert np.array_equal(leaves, flat.apply(q))


def test_inputs_at_the_thresholds_go_where_sklearn_sends_them(data):
    """The walk compares in float32; values on and right beside each float64 threshold
    must still take scikit-learn's branch."""
    x, y = data
    model = ExtraTreesClassifier(n_estimators=10, random_state=0).fit(x, y)
    flat = FlatForest.from_sklearn(model)
    feature = np.concatenate([e.tree_.feature for e in model.estimators_])
    threshold = np.concatenate([e.tree_.threshold for e in model.estimators_])
    internal = feature >= 0
    rows = []
    for f, t in zip(feature[internal][:200], threshold[internal][:200], strict=True):
        t32 = np.float32(t)
        for v in (
            t32,
            np.nextafter(t32, np.float32(-np.inf)),
            np.nextafter(t32, np.float32(np.inf)),
        ):
            row = x[len(rows) % len(x)].copy()
            row[f] = v
            rows.append(row)
    q = np.asarray(rows, np.float32)
    assert np.array_equal(flat.apply(q) - flat.roots[None, :], model.apply(q))


def test_an_empty_batch_and_single_leaf_trees(data):
    x, y = data
    flat = FlatForest.from_sklearn(ExtraTreesClassifier(n_estimators=3, random_state=0).fit(x, y))
    assert flat.apply(x[:0]).shape == (0, 3) and flat.predict_proba(x[:0]).shape == (0, 4)
    stump = ExtraTreesClassifier(n_estimators=2, max_depth=1, random_state=0).fit(x, y)
    one_leaf = ExtraTreesClassifier(n_estimators=2, random_state=0).fit(x, np.zeros(len(x), int))
    for model in (stump, one_leaf):  # a tree may be a lone leaf: its root is its answer
        f = FlatForest.from_sklearn(model)
        assert np.array_equal(f.apply(x) - f.roots[None, :], model.apply(x))


def test_state_is_plain_arrays_and_round_trips(data):
    x, y = data
    flat = FlatForest.from_sklearn(ExtraTreesClassifier(n_estimators=10, random_state=0).fit(x, y))
    buf = io.BytesIO()
    np.savez(buf, **flat.get_state())
    buf.seek(0)
    with np.load(buf, allow_pickle=False) as npz:
        state = {k: npz[k] for k in npz.files}
    assert all(v.dtype.kind in "iuf" for v in state.values())
    again = FlatForest.from_state(state, flat.n_classes, flat.n_features)
    assert np.array_equal(again.predict_proba(x), flat.predict_proba(x))


def test_rejects_bad_state_and_inputs(data):
    x, y = data
    flat = FlatForest.from_sklearn(ExtraTreesClassifier(n_estimators=5, random_state=0).fit(x, y))
    state = flat.get_state()
    with pytest.raises(ValueError, match="lacks"):
        FlatForest.from_state({k: v for k, v in state.items() if k != "roots"}, 4, 7)
    nodes = state["nodes"]
    internal = nodes[:, 0] >= 0

    def with_left(left):
        changed = nodes.copy()
        changed[internal, 2] = left
        return dict(state, nodes=changed)

    with pytest.raises(ValueError, match="out of range"):
        FlatForest.from_state(with_left(10**6), 4, 7)
    with pytest.raises(ValueError, match="out of range"):
        FlatForest.from_state(state, 4, 2)  # split features beyond the input width
    with pytest.raises(ValueError, match="after their parent"):
        FlatForest.from_state(with_left(0), 4, 7)  # back to the root
    with pytest.raises(ValueError, match=r"\(nodes, 4\)"):
        FlatForest.from_state(dict(state, nodes=nodes[:, :3]), 4, 7)
    first_leaf = np.flatnonzero(~internal)[0]

    def with_leaf(column, value):
        changed = nodes.copy()
        changed[first_leaf, column] = value
        return dict(state, nodes=changed)

    with pytest.raises(ValueError, match="leaf records"):
        FlatForest.from_state(with_leaf(0, -5), 4, 7)
    with pytest.raises(ValueError, match="leaf classes"):
        FlatForest.from_state(with_leaf(3, 4), 4, 7)  # answers a class beyond K
    with pytest.raises(ValueError, match="leaf distributions"):
        # a mixed distribution beyond those stored
        FlatForest.from_state(with_leaf(3, -len(state["mixed_ptr"])), 4, 7)
    with pytest.raises(ValueError, match="leaf distributions"):  # beyond the stored entries
        FlatForest.from_state(dict(state, mixed_ptr=np.asarray([0, 5])), 4, 7)
    with pytest.raises(ValueError, match="shape"):
        flat.predict_proba(x[:, :3])


def test_refuses_classes_it_cannot_index(data):
    x, y = data
    with pytest.raises(ValueError, match="0 … K-1"):
        FlatForest.from_sklearn(ExtraTreesClassifier(n_estimators=3, random_state=0).fit(x, y + 5))
