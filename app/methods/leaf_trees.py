"""Extremely randomised trees grown on a leaf's few samples, for promotions
(``FlatForest.with_samples``): compiled, one call a leaf.

A promotion at 10,000 objects grows ~10,000 such trees of a few samples each (a reached
leaf's samples, seen and new, in each of the 100 trees of the whole model and of each
procedure's). scikit-learn's ``ExtraTreeClassifier`` grew the same kind of tree in 1.8 ms a
leaf, 1.5 ms of which checked its inputs (``type_of_target``, which its public ``fit``
runs even with ``check_input=False``): 17.8 of a promotion's 36 s (cProfile, scikit-learn
1.9.1, 2026-11-26). This is its algorithm (``RandomSplitter`` with the Gini criterion,
depth first, grown until every leaf is pure or no feature varies), drawing its random
numbers from numba's generator instead, so the trees differ from scikit-learn's with the
same seed but are grown by the same rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

FEATURE_THRESHOLD = 1e-7  # scikit-learn's: a feature this flat does not split


@dataclass(frozen=True)
class LeafTree:
    """A grown tree: per node its split ``feature`` (-2 at a leaf), ``threshold``,
    ``children_left`` / ``children_right`` (-1 at a leaf), and, per node, the class counts
    ``value`` (nodes, len(classes)) and ``n_node_samples``; ``classes`` are the labels the
    counts' columns stand for. Nodes are numbered depth first, children after parents."""

    feature: np.ndarray
    threshold: np.ndarray
    children_left: np.ndarray
    children_right: np.ndarray
    value: np.ndarray
    n_node_samples: np.ndarray
    classes: np.ndarray

    @property
    def node_count(self) -> int:
        return len(self.feature)


def n_split_features(max_features: Any, n_features: int) -> int:
    """How many features a node tries (scikit-learn's reading of ``max_features``)."""
    if max_features is None:
        return n_features
    if max_features == "sqrt":
        return max(1, int(math.sqrt(n_features)))
    if max_features == "log2":
        return max(1, int(math.log2(n_features)))
    if isinstance(max_features, int | np.integer) and not isinstance(max_features, bool):
        return min(n_features, max(1, int(max_features)))
    if isinstance(max_features, float | np.floating):
        return min(n_features, max(1, int(max_features * n_features)))
    raise ValueError(f"max_features must be 'sqrt', 'log2', a number or None, not {max_features!r}")


def grow_leaf(x: np.ndarray, y: np.ndarray, max_features: Any, seed: int) -> LeafTree:
    """An extremely randomised tree on samples ``x`` (N, D) of labels ``y`` (N,), grown
    until its leaves are pure or no feature varies in them; ``seed`` fixes it."""
    x = np.ascontiguousarray(x, np.float32)
    classes, codes = np.unique(np.asarray(y), return_inverse=True)
    if x.ndim != 2 or len(x) != len(codes) or len(x) == 0:
        raise ValueError(f"grow_leaf needs (N, D) samples and N labels, N >= 1; got {x.shape}")
    tries = n_split_features(max_features, x.shape[1])
    feature, threshold, left, right, value, n_samples = _grow(
        x, codes.astype(np.int64), len(classes), tries, int(seed)
    )
    return LeafTree(feature, threshold, left, right, value, n_samples, classes)


@njit(cache=True, nogil=True)
def _grow(x, y, k, tries, seed):
    np.random.seed(seed)
    n, d = x.shape
    most = 2 * n - 1  # a tree of pure leaves has at most n leaves
    feature = np.full(most, -2, np.int64)
    threshold = np.full(most, -2.0)
    left = np.full(most, -1, np.int64)
    right = np.full(most, -1, np.int64)
    value = np.zeros((most, k))
    n_samples = np.zeros(most, np.int64)
    order = np.arange(n)
    features = np.arange(d)
    stack = np.empty((most, 3), np.int64)  # (node, first, end) of order
    stack[0] = (0, 0, n)
    depth, count = 1, 1
    counts_l = np.zeros(k)
    while depth > 0:
        depth -= 1
        node, s, e = stack[depth]
        for i in range(s, e):
            value[node, y[order[i]]] += 1.0
        n_samples[node] = e - s
        if e - s < 2 or value[node].max() == e - s:
            continue  # one sample, or one class: a leaf
        best, best_f, best_t = -np.inf, -1, 0.0
        left_to_draw, found = d, 0
        while left_to_draw > 0 and found < tries:
            j = np.random.randint(0, left_to_draw)
            f = features[j]
            features[j], features[left_to_draw - 1] = features[left_to_draw - 1], f
            left_to_draw -= 1
            lo, hi = np.inf, -np.inf
            for i in range(s, e):
                v = x[order[i], f]
                lo, hi = min(lo, v), max(hi, v)
            if hi <= lo + FEATURE_THRESHOLD:
                continue  # constant here: does not count as tried
            found += 1
            t = lo + np.random.random() * (hi - lo)
            if t >= hi:
                t = lo
            counts_l[:] = 0.0
            n_l = 0
            for i in range(s, e):
                if x[order[i], f] <= t:
                    counts_l[y[order[i]]] += 1.0
                    n_l += 1
            n_r = e - s - n_l
            # Gini's proxy: the improvement grows with sum_c n_lc^2 / n_l + sum_c n_rc^2 / n_r
            score_l = score_r = 0.0
            for c in range(k):
                score_l += counts_l[c] * counts_l[c]
                r = value[node, c] - counts_l[c]
                score_r += r * r
            score = score_l / n_l + score_r / n_r
            if score > best:
                best, best_f, best_t = score, f, t
        if best_f < 0:
            continue  # no feature varies: a leaf
        lo_at, hi_at = s, e - 1  # partition order[s:e]: samples <= t first
        while lo_at <= hi_at:
            if x[order[lo_at], best_f] <= best_t:
                lo_at += 1
            else:
                order[lo_at], order[hi_at] = order[hi_at], order[lo_at]
                hi_at -= 1
        feature[node], threshold[node] = best_f, best_t
        left[node], right[node] = count, count + 1
        stack[depth] = (count + 1, lo_at, e)  # the right child after the left one
        stack[depth + 1] = (count, s, lo_at)
        depth += 2
        count += 2
    return (
        feature[:count],
        threshold[:count],
        left[:count],
        right[:count],
        value[:count],
        n_samples[:count],
    )
