"""The compiled Gini grower (``app.methods.gini_trees``) against the rule it claims:
scikit-learn's extremely randomised trees, grown until pure, the split of best Gini."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from sklearn.ensemble import ExtraTreesClassifier

from app.data.simulator import simulate_dataset
from app.framework.scaling import RobustInputScaler, flatten
from app.methods.forest import FlatForest
from app.methods.gini_trees import SMALL_NODE, grow_trees
from app.methods.leaf_trees import FEATURE_THRESHOLD, n_split_features


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


# ------------------------------------------------------------------ reference grower
# The same random draws: numba's generator is one state per thread, shared by every
# compiled function, so these draw the very numbers ``_grow`` draws after the same seed.
@njit
def _seed(seed):
    np.random.seed(seed)


@njit
def _randint(n):
    return np.random.randint(0, n)


@njit
def _uniform():
    return np.random.random()


def _gini(counts: np.ndarray) -> float:
    n = counts.sum()
    return 1.0 - float(((counts / n) ** 2).sum())


def _gini_gain(y: np.ndarray, go_left: np.ndarray, k: int) -> float:
    """The decrease of Gini impurity by a split, counted the plain way."""
    n, n_left = len(y), int(go_left.sum())
    parent = _gini(np.bincount(y, minlength=k))
    left = _gini(np.bincount(y[go_left], minlength=k))
    right = _gini(np.bincount(y[~go_left], minlength=k))
    return parent - n_left / n * left - (n - n_left) / n * right


def _proxy(y: np.ndarray, go_left: np.ndarray, k: int) -> float:
    """``sum_c L_c^2 / n_L + sum_c R_c^2 / n_R``, which orders splits as their Gini gain
    does, in the grower's floating-point operations: splits of equal gain (common on small
    data) are then told apart by the same rounding, so the same one is kept."""
    left, right = (np.bincount(y[side], minlength=k) for side in (go_left, ~go_left))
    return int((left**2).sum()) / int(left.sum()) + int((right**2).sum()) / int(right.sum())


def _reference_tree(x, y, k, tries, seed, small_node):
    """The grower's rule written plainly: depth first, left child first, children
    numbered after their parent; each node draws features without replacement from one
    permutation kept across nodes (as the grower does), skips features constant in it,
    draws one uniform threshold per feature tried, and keeps the split of largest
    ``_proxy`` (the first on a tie). Nodes of at most ``small_node`` samples are grown
    after every larger one, each subtree whole. Also returns every node's candidates,
    with their Gini gain counted by brute force."""
    d = x.shape[1]
    features = list(range(d))
    feature, threshold, left, right = [-1], [np.float32(0)], [-1], [-1]
    leaf_of_sample = np.full(len(x), -1)
    candidates: dict[int, list[tuple[int, np.float32, float, float]]] = {}
    deferred = []

    def new_node() -> int:
        feature.append(-1), threshold.append(np.float32(0)), left.append(-1), right.append(-1)
        return len(feature) - 1

    def grow(node, samples, defer):
        if defer and len(samples) <= small_node:
            deferred.append((node, samples))
            return
        labels = y[samples]
        tried, to_draw = [], d
        while len(np.unique(labels)) > 1 and to_draw > 0 and len(tried) < tries:
            j = _randint(to_draw)
            f = features[j]
            features[j], features[to_draw - 1] = features[to_draw - 1], f
            to_draw -= 1
            values = x[samples, f]
            lo, hi = float(values.min()), float(values.max())
            if hi <= lo + FEATURE_THRESHOLD:
                continue
            t = np.float32(lo + _uniform() * (hi - lo))
            if t >= hi:
                t = np.float32(lo)
            go_left = values <= t
            tried.append((f, t, _gini_gain(labels, go_left, k), _proxy(labels, go_left, k)))
        candidates[node] = tried
        if not tried:
            leaf_of_sample[samples] = node
            return
        f, t, _, _ = max(tried, key=lambda c: c[3])  # the first of the largest
        go_left = x[samples, f] <= t
        feature[node], threshold[node] = f, t
        left[node], right[node] = new_node(), new_node()
        grow(left[node], samples[go_left], defer)
        grow(right[node], samples[~go_left], defer)

    _seed(seed)
    grow(0, np.arange(len(x)), defer=small_node > 0)
    for node, samples in deferred:
        grow(node, samples, defer=False)
    arrays = [np.asarray(a) for a in (feature, threshold, left, right)]
    return (*arrays, leaf_of_sample), candidates


@pytest.fixture(scope="module")
def small():
    """90 samples of 5 classes and 7 features: one constant, two of few distinct values
    (ties at the threshold), the rest noisy and telling classes apart in part."""
    rng = np.random.default_rng(11)
    y = rng.integers(0, 5, 90)
    x = rng.normal(size=(90, 7)) + 0.8 * y[:, None] * rng.random(7)
    x[:, 2] = 1.5
    x[:, 4] = rng.integers(0, 3, 90)
    x[:, 5] = np.round(x[:, 5])
    return x.astype(np.float32), y


@pytest.mark.parametrize("small_node", [0, 6])
@pytest.mark.parametrize("max_features", [None, 2, "sqrt"])
def test_trees_equal_a_plain_reference_node_for_node_given_the_same_draws(
    small, small_node, max_features
):
    """Each chosen split is the candidate of largest Gini gain counted by brute force
    (``_gini_gain``), and every tree equals the plain reference's, node for node, when
    both draw the same random numbers."""
    x, y = small
    k = 5
    tries = n_split_features(max_features, x.shape[1])
    seeds = np.random.SeedSequence(4).generate_state(6)
    grown = grow_trees(x, y, k, 6, max_features, 4, small_node=small_node)
    for tree, seed in zip(grown, seeds, strict=True):
        (feature, threshold, left, right, leaf_of_sample), candidates = _reference_tree(
            x, y, k, tries, int(seed), small_node
        )
        np.testing.assert_array_equal(tree.feature, feature)
        np.testing.assert_array_equal(tree.threshold, threshold.astype(np.float32))
        np.testing.assert_array_equal(tree.children_left, left)
        np.testing.assert_array_equal(tree.children_right, right)
        np.testing.assert_array_equal(tree.leaf_of_sample, leaf_of_sample)
        reached = np.zeros(len(x), np.int64)  # the samples of each node, routed down
        inner = 0
        for node in range(tree.node_count):
            at = np.flatnonzero(_reaches(tree, x, node))
            if tree.feature[node] < 0:
                continue
            inner += 1
            go_left = x[at, tree.feature[node]] <= tree.threshold[node]
            assert 0 < go_left.sum() < len(at)
            gain = _gini_gain(y[at], go_left, k)
            # the largest Gini gain of the node's candidates (ties within rounding)
            assert gain >= max(c[2] for c in candidates[node]) - 1e-12, node
            if max_features is None:  # every varying feature tried: none does better
                varying = np.ptp(x[at], axis=0) > FEATURE_THRESHOLD
                assert len(candidates[node]) == varying.sum()
            reached[at] += 1
        assert inner >= 5 and (reached > 0).all()


def _reaches(tree, x, node) -> np.ndarray:
    """(N,) whether each sample's path from the root passes ``node``."""
    here = np.zeros(len(x), np.int64)
    passed = here == node
    while True:
        inner = tree.children_left[here] >= 0
        if not inner.any():
            return passed
        at = here[inner]
        go_left = x[inner, tree.feature[at]] <= tree.threshold[at]
        here[inner] = np.where(go_left, tree.children_left[at], tree.children_right[at])
        passed |= here == node
