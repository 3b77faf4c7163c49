"""The leaf trees a promotion grows (``app.methods.leaf_trees``): scikit-learn's
extremely randomised tree rule, compiled. Checked here: every training sample ends in a
leaf of its own label when the samples differ, a split lies between its node's extremes,
the same seed grows the same tree, identical samples of two labels stay in one mixed
leaf, ``max_features`` is read as scikit-learn reads it, and bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest

from app.methods.leaf_trees import grow_leaf, n_split_features


def _leaf(tree, row: np.ndarray) -> int:
    node = 0
    while tree.children_left[node] >= 0:
        go_left = row[tree.feature[node]] <= tree.threshold[node]
        node = tree.children_left[node] if go_left else tree.children_right[node]
    return node


@pytest.mark.parametrize("n", [2, 5, 17, 40])
def test_distinct_samples_end_in_leaves_of_their_own_label(n):
    rng = np.random.default_rng(n)
    x = rng.normal(size=(n, 60)).astype(np.float32)
    y = rng.integers(0, 3, n) + 1000  # labels as a grown forest's leaves hold them
    tree = grow_leaf(x, y, "sqrt", seed=7)
    leaves = tree.children_left < 0
    assert tree.node_count == 2 * leaves.sum() - 1  # every split has two children
    internal = np.flatnonzero(~leaves)
    assert (tree.children_left[internal] > internal).all()  # children after parents
    assert (tree.children_right[internal] > internal).all()
    for i in range(n):
        at = _leaf(tree, x[i])
        counts = tree.value[at]
        assert counts.max() == counts.sum()  # pure
        assert tree.classes[counts.argmax()] == y[i]
    np.testing.assert_array_equal(
        tree.value[leaves].sum(axis=0), np.unique(y, return_counts=True)[1]
    )
    assert tree.n_node_samples[0] == n and (tree.n_node_samples[leaves] >= 1).all()


def test_splits_lie_between_the_extremes_of_their_node_and_a_seed_repeats_a_tree():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(30, 16)).astype(np.float32)
    y = rng.integers(0, 4, 30)
    tree = grow_leaf(x, y, "sqrt", seed=3)
    assert tree.children_left[0] >= 0
    lo, hi = x[:, tree.feature[0]].min(), x[:, tree.feature[0]].max()
    assert lo <= tree.threshold[0] < hi
    again = grow_leaf(x, y, "sqrt", seed=3)
    for key in ("feature", "threshold", "children_left", "children_right", "value"):
        np.testing.assert_array_equal(getattr(tree, key), getattr(again, key))
    other = grow_leaf(x, y, "sqrt", seed=4)
    assert not np.array_equal(tree.threshold, other.threshold)


def test_identical_samples_of_two_labels_stay_in_one_mixed_leaf():
    x = np.repeat(np.eye(2, 8, dtype=np.float32), 3, axis=0)  # two points, three copies each
    y = np.array([0, 1, 0, 1, 0, 1])
    tree = grow_leaf(x, y, None, seed=0)
    leaves = np.flatnonzero(tree.children_left < 0)
    assert len(leaves) == 2  # split once, then nothing varies
    np.testing.assert_array_equal(tree.value[leaves].sum(axis=1), [3, 3])
    assert (tree.value[leaves] > 0).all()
    lone = grow_leaf(x[:1], y[:1], "sqrt", seed=0)
    assert lone.node_count == 1 and lone.children_left[0] == -1


def test_max_features_is_read_as_scikit_learn_reads_it_and_bad_input_is_refused():
    assert n_split_features("sqrt", 960) == 30 and n_split_features("log2", 960) == 9
    assert n_split_features(0.5, 10) == 5 and n_split_features(25, 10) == 10
    assert n_split_features(None, 7) == 7 and n_split_features(0.01, 10) == 1
    with pytest.raises(ValueError, match="max_features"):
        n_split_features("all", 10)
    with pytest.raises(ValueError, match="samples and N labels"):
        grow_leaf(np.zeros((3, 4), np.float32), np.zeros(2), "sqrt", 0)
    with pytest.raises(ValueError, match="samples and N labels"):
        grow_leaf(np.zeros((0, 4), np.float32), np.zeros(0), "sqrt", 0)
