"""The compiled Gini grower (``app.methods.gini_trees``) against the rule it claims:
scikit-learn's extremely randomised trees, grown until pure, the split of best Gini."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.ensemble import ExtraTreesClassifier

from app.data.simulator import simulate_dataset
from app.framework.scaling import RobustInputScaler, flatten
from app.methods.forest import FlatForest
from app.methods.gini_trees import SMALL_NODE, grow_trees


@pytest.fixture(scope="module")
def sim():
    """40 simulated objects, 8 trials each: 6 train, 2 test; more samples than a block."""
    ds = simulate_dataset(40, 8, seed=3)
    test = (ds.trials % 8) >= 6
    z = RobustInputScaler().fit(flatten(ds.samples[~test])).transform(flatten(ds.samples))
    assert (~test).sum() > 2 * SMALL_NODE  # the small-node blocks are taken
    return z.astype(np.float32), ds.labels, test


def _walk(tree, x):
    node = np.zeros(len(x), np.int64)
    while True:
        inner = tree.children_left[node] >= 0
        if not inner.any():
            return node
        at = node[inner]
        go_left = x[inner, tree.feature[at]] <= tree.threshold[at]
        node[inner] = np.where(go_left, tree.children_left[at], tree.children_right[at])


@pytest.mark.parametrize("small_node", [SMALL_NODE, 0, 7])
def test_trees_are_pure_and_say_where_each_training_sample_ends(sim, small_node):
    z, y, test = sim
    for tree in grow_trees(z[~test], y[~test], 40, 3, "sqrt", 0, small_node=small_node):
        leaf = tree.children_left < 0
        inner = np.flatnonzero(~leaf)
        # children after their parent, every node but the root a child once
        assert (tree.children_left[inner] > inner).all()
        assert (tree.children_right[inner] > inner).all()
        kids = np.sort(np.r_[tree.children_left[inner], tree.children_right[inner]])
        np.testing.assert_array_equal(kids, np.arange(1, tree.node_count))
        assert (tree.feature[leaf] == -1).all() and tree.threshold.dtype == np.float32
        reached = _walk(tree, z[~test])
        np.testing.assert_array_equal(reached, tree.leaf_of_sample)
        for node in np.unique(reached):  # distinct samples: grown until one class a leaf
            assert len(np.unique(y[~test][reached == node])) == 1


def test_a_tree_depends_on_its_seed_alone(sim):
    z, y, test = sim
    one = list(grow_trees(z[~test], y[~test], 40, 4, "sqrt", 7, n_jobs=1))
    two = list(grow_trees(z[~test], y[~test], 40, 4, "sqrt", 7, n_jobs=2))
    other = next(iter(grow_trees(z[~test], y[~test], 40, 1, "sqrt", 8)))
    for a, b in zip(one, two, strict=True):
        for name in ("feature", "threshold", "children_left", "leaf_of_sample"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert one[0].node_count != other.node_count or (one[0].feature != other.feature).any()


def test_the_order_of_the_samples_changes_nothing(sim):
    """Split scores are exact counts, whatever order the classes come in (the grower counts
    runs of one class at once): shuffled samples grow the same splits."""
    z, y, test = sim
    x, labels = z[~test], y[~test]
    shuffle = np.random.default_rng(0).permutation(len(x))
    a = next(iter(grow_trees(x, labels, 40, 1, "sqrt", 3)))
    b = next(iter(grow_trees(x[shuffle], labels[shuffle], 40, 1, "sqrt", 3)))
    for name in ("feature", "threshold", "children_left", "children_right"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(a.leaf_of_sample[shuffle], b.leaf_of_sample)


def test_the_split_of_best_gini_is_kept():
    """Every feature tried at the root (max_features None): the one feature whose classes
    lie apart separates them, whatever threshold in its gap is drawn; noise features do not."""
    rng = np.random.default_rng(1)
    y = np.repeat([0, 1], 200)
    x = rng.normal(size=(400, 12)).astype(np.float32)
    x[:, 5] = y * 10.0 + rng.uniform(0, 0.1, 400)
    for tree in grow_trees(x, y, 2, 10, None, 0):
        assert tree.feature[0] == 5 and tree.node_count == 3


def test_it_recognises_as_scikit_learns_classifier_does(sim):
    z, y, test = sim
    grown = FlatForest.grow(z[~test], y[~test], 40, 60, "sqrt", 0, 2)
    assert grown.n_trees == 60 and len(grown.mixed_class) == 0
    sk = ExtraTreesClassifier(60, max_features="sqrt", random_state=0).fit(z[~test], y[~test])
    ours = (grown.predict_proba(z[test]).argmax(axis=1) == y[test]).mean()
    theirs = (sk.predict(z[test]) == y[test]).mean()
    assert ours > 0.5 and abs(ours - theirs) < 0.1, (ours, theirs)
    again = FlatForest.from_state(grown.get_state(), 40, z.shape[1])
    assert again.predict_proba(z[test]).tobytes() == grown.predict_proba(z[test]).tobytes()


def test_samples_no_feature_tells_apart_share_a_leaf():
    x = np.ones((6, 3), np.float32)
    y = np.array([0, 0, 1, 2, 2, 2])
    tree = next(iter(grow_trees(x, y, 3, 1, "sqrt", 0)))
    assert tree.node_count == 1 and (tree.leaf_of_sample == 0).all()
    forest = FlatForest.grow(x, y, 3, 2, "sqrt", 0, 1)
    np.testing.assert_allclose(forest.predict_proba(x[:1])[0], [2 / 6, 1 / 6, 3 / 6])


@pytest.mark.parametrize(
    ("x", "y", "message"),
    [
        (np.zeros((3, 2)), np.array([0, 1, 3]), "classes must be integers in 0 … 2"),
        (np.zeros((3, 2)), np.array([0.0, 1.0, 2.0]), "classes must be integers"),
        (np.array([[0.0, np.nan]] * 3), np.array([0, 1, 2]), "finite samples"),
        (np.zeros((3, 2)), np.array([0, 1]), "N labels"),
        (np.zeros(3), np.array([0, 1, 2]), r"\(N, D\) samples"),
    ],
)
def test_bad_inputs_are_refused_with_what_is_wrong(x, y, message):
    with pytest.raises(ValueError, match=message):
        next(iter(grow_trees(x, y, 3, 1, "sqrt", 0)))


def test_a_negative_small_node_is_refused():
    with pytest.raises(ValueError, match="small_node must be 0 or more"):
        grow_trees(np.zeros((3, 2)), np.array([0, 1, 2]), 3, 1, "sqrt", 0, small_node=-1)


def test_an_unknown_grower_is_refused():
    with pytest.raises(ValueError, match="grower must be 'gini' or 'sklearn'"):
        FlatForest.grow(np.zeros((3, 2)), np.array([0, 1, 2]), 3, 1, "sqrt", 0, 1, "xgboost")
