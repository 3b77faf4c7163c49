"""Extremely randomised trees grown on all the training samples with the exact Gini
criterion, compiled (``FlatForest.grow``'s default grower).

scikit-learn's ``ExtraTreesClassifier`` keeps a K-wide class distribution in every node
(out of memory near 2,000 objects); its regressor grown on a 32-dim random code per class
(``FlatForest.grow(grower="sklearn")``) avoids that, but spends about half of its time
updating the 32 code sums of every sample that a candidate split moves. This grower
draws splits as scikit-learn's ``RandomSplitter`` does (``max_features`` features tried
per node, features constant in the node not counted, one uniform threshold each between
the node's minimum and maximum) and keeps the one with the best Gini proxy
``sum_c L_c^2 / n_L + sum_c R_c^2 / n_R``, counted exactly in O(samples) per candidate:
the node's class counts ``N_c`` are counted once, and for a candidate only the left
counts, ``sum R_c^2 = sum N_c^2 - 2 sum N_c L_c + sum L_c^2``. Trees grow until every
leaf is one class or no feature varies in it. Numbers come from numba's generator, so a
tree differs from scikit-learn's with the same seed, but is grown by the same rule.

Where the time goes is memory, not arithmetic: a candidate gathers one feature of the
node's samples, and once a node is small those reads land in a different cache line
each. Features are kept feature-major (one row per feature, read forwards: a node's
samples stay in index order, partitioned stably), and a node of at most ``small_node``
samples has its samples' features copied into a block of their own, row-major reads,
before its subtree is grown from the block, which stays in cache. On the 30,000
training samples of 3,000 simulated objects, one thread (``bench.grower``, EPYC VM,
2026-11-27): 55 ms a tree on one procedure's 240 features and 152 ms on all 960, against
166 and 291 ms for scikit-learn's code regressor; without the blocks, 71 and 252 ms.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from numba import njit

from app.methods.leaf_trees import FEATURE_THRESHOLD, n_split_features

#: a node of at most this many samples grows its subtree from a block of its own
#: (``bench.grower --small-nodes``: docs/BENCHMARKS.md)
SMALL_NODE = 64


@dataclass(frozen=True)
class GrownTree:
    """One tree: per node its split ``feature`` (-1 at a leaf), float32 ``threshold``
    (a sample goes left when its feature is <= it), ``children_left`` /
    ``children_right`` (-1 at a leaf), numbered depth first with children after their
    parent; ``leaf_of_sample`` (N,) is the leaf node each training sample ends in."""

    feature: np.ndarray
    threshold: np.ndarray
    children_left: np.ndarray
    children_right: np.ndarray
    leaf_of_sample: np.ndarray

    @property
    def node_count(self) -> int:
        return len(self.feature)


def grow_trees(
    x: np.ndarray,
    y: np.ndarray,
    n_classes: int,
    n_trees: int,
    max_features: Any,
    seed: int,
    n_jobs: int | None = 1,
    small_node: int = SMALL_NODE,
) -> Iterator[GrownTree]:
    """``n_trees`` trees on samples ``x`` (N, D) of classes ``y`` in 0 … ``n_classes``-1,
    grown ``n_jobs`` at a time in threads (joblib's reading of ``n_jobs``) and yielded in
    order as they are done, so that a caller holds few at once; tree i is fixed by
    ``seed`` and i alone, whatever ``n_jobs``. ``small_node``: nodes of at most this many
    samples are grown from a copy of their own (0: none); it changes the order in which
    nodes draw their random numbers, so the trees, not the rule they are grown by."""
    x = np.ascontiguousarray(x, np.float32)
    y = np.asarray(y)
    if x.ndim != 2 or len(x) == 0 or y.shape != (len(x),):
        raise ValueError(f"grow_trees needs (N, D) samples and N labels, N >= 1; got {x.shape}")
    if not (np.isfinite(x.min()) and np.isfinite(x.max())):  # NaN or inf: no N x D mask
        raise ValueError("grow_trees needs finite samples")
    if not np.issubdtype(y.dtype, np.integer) or y.min() < 0 or y.max() >= n_classes:
        raise ValueError(f"sample classes must be integers in 0 … {n_classes - 1}")
    if n_trees < 1:
        raise ValueError(f"n_trees must be at least 1, not {n_trees}")
    if small_node < 0:
        raise ValueError(f"small_node must be 0 or more, not {small_node}")
    tries = n_split_features(max_features, x.shape[1])
    by_feature = np.ascontiguousarray(x.T)
    labels = np.asarray(y, np.int64)  # _grow works on a copy of its own
    seeds = np.random.SeedSequence(seed).generate_state(n_trees)

    def one(tree_seed: int) -> GrownTree:
        return GrownTree(
            *_grow(x, by_feature, labels, int(n_classes), tries, tree_seed, int(small_node))
        )

    parallel = Parallel(n_jobs=n_jobs, prefer="threads", return_as="generator")
    return parallel(delayed(one)(int(s)) for s in seeds)


@njit(cache=True, nogil=True)
def _grow(x, by_feature, y, k, tries, seed, local):
    np.random.seed(seed)  # numba's generator is per thread: this tree's draws are its own
    n, d = x.shape
    most = 2 * n - 1  # pure leaves: at most n of them
    out = (
        np.full(most, -1, np.int32),  # feature
        np.zeros(most, np.float32),  # threshold
        np.full(most, -1, np.int32),  # left
        np.full(most, -1, np.int32),  # right
        np.empty(n, np.int32),  # leaf_of_sample
    )
    order = np.arange(n).astype(np.int32)  # samples, node by node
    labels = y.copy()  # their classes, in the same order
    work = _scratch(n, k, d, most)
    count, n_small = _split_nodes(
        by_feature, order, labels, order.copy(), 0, n, 0, 1, tries, local, out, work
    )
    # each small node's samples copied together, then its subtree grown from the copy
    block = np.empty((d, local), np.float32)
    local_order = np.arange(local).astype(np.int32)
    local_labels = np.empty(local, np.int64)
    local_ids = np.empty(local, np.int32)
    small = work[-1][:n_small].copy()
    for q in range(n_small):
        node, s, e = small[q, 0], small[q, 1], small[q, 2]
        m = e - s
        for i in range(m):
            sample = order[s + i]
            for f in range(d):
                block[f, i] = x[sample, f]
            local_order[i] = i
            local_labels[i] = labels[s + i]
            local_ids[i] = sample
        count, _ = _split_nodes(
            block, local_order, local_labels, local_ids, 0, m, node, count, tries, 0, out, work
        )
    feature, threshold, left, right, leaf_of_sample = out
    return feature[:count], threshold[:count], left[:count], right[:count], leaf_of_sample


@njit(cache=True, nogil=True)
def _scratch(n, k, d, most):
    """Scratch arrays of one tree, reused by every node."""
    return (
        np.zeros(k, np.int64),  # the node's class counts
        np.zeros(k, np.int64),  # a candidate's left class counts
        np.empty(n, np.float32),  # the candidate feature of the node's samples
        np.empty(n, np.int32),  # partition: samples going right
        np.empty(n, np.int64),  # and their classes
        np.arange(d),  # features, shuffled as they are drawn
        np.empty((most, 3), np.int64),  # nodes to split: (node, first, end) of ``order``
        np.empty((n, 3), np.int64),  # small nodes left for their own blocks
    )


@njit(cache=True, nogil=True)
def _split_nodes(rows, order, labels, ids, first, end, root, count, tries, small_below, out, work):
    """Grow node ``root`` on samples ``order[first:end]`` (columns of the feature-major
    ``rows``; ``ids`` maps them to training samples). A node of at most ``small_below``
    samples is left unsplit and listed in ``work``'s small nodes. Returns the node count
    and the number of small nodes."""
    feature, threshold, left, right, leaf_of_sample = out
    cnt, cl, values, right_order, right_labels, features, stack, small = work
    d = rows.shape[0]
    n_small = 0
    stack[0, 0], stack[0, 1], stack[0, 2] = root, first, end
    depth = 1
    while depth > 0:
        depth -= 1
        node, s, e = stack[depth, 0], stack[depth, 1], stack[depth, 2]
        m = e - s
        if m <= small_below:
            small[n_small, 0], small[n_small, 1], small[n_small, 2] = node, s, e
            n_small += 1
            continue
        total_sq, distinct = 0, 0  # sum_c N_c^2, and how many classes
        for i in range(s, e):
            c = labels[i]
            a = cnt[c]
            if a == 0:
                distinct += 1
            total_sq += 2 * a + 1
            cnt[c] = a + 1
        best, best_f, best_t = -1.0, -1, np.float32(0.0)
        to_draw, found = d, 0
        while distinct > 1 and to_draw > 0 and found < tries:
            j = np.random.randint(0, to_draw)
            f = features[j]
            features[j], features[to_draw - 1] = features[to_draw - 1], f
            to_draw -= 1
            row = rows[f]
            lo, hi = np.inf, -np.inf
            for i in range(s, e):
                v = row[order[i]]
                values[i] = v
                lo, hi = min(lo, v), max(hi, v)
            if hi <= lo + FEATURE_THRESHOLD:
                continue  # constant here: does not count as tried
            found += 1
            t = np.float32(lo + np.random.random() * (hi - lo))
            if t >= hi:
                t = np.float32(lo)
            # left counts; a class's samples lie together (index order), so a run of them
            # is counted in a register and its counter touched once per run
            sl, cross, nl = 0, 0, 0  # sum_c L_c^2, sum_c N_c L_c, n_L
            run_c, run_n = labels[s], 0
            for i in range(s, e):
                c = labels[i]
                if c != run_c:
                    a = cl[run_c]
                    sl += run_n * (2 * a + run_n)
                    cross += run_n * cnt[run_c]
                    cl[run_c] = a + run_n
                    nl += run_n
                    run_c, run_n = c, 0
                run_n += np.int64(values[i] <= t)
            a = cl[run_c]
            sl += run_n * (2 * a + run_n)
            cross += run_n * cnt[run_c]
            nl += run_n
            for i in range(s, e):
                cl[labels[i]] = 0
            score = sl / nl + (total_sq - 2 * cross + sl) / (m - nl)
            if score > best:
                best, best_f, best_t = score, f, t
        for i in range(s, e):
            cnt[labels[i]] = 0
        if best_f < 0:  # one class, or no feature varies: a leaf
            for i in range(s, e):
                leaf_of_sample[ids[order[i]]] = node
            continue
        # stable partition: a node's samples stay in index order, so its children's
        # gathers read each feature row forwards
        row, at, r = rows[best_f], s, 0
        for i in range(s, e):
            sample = order[i]
            if row[sample] <= best_t:
                order[at], labels[at] = sample, labels[i]
                at += 1
            else:
                right_order[r], right_labels[r] = sample, labels[i]
                r += 1
        order[at:e] = right_order[:r]
        labels[at:e] = right_labels[:r]
        feature[node], threshold[node] = best_f, best_t
        left[node], right[node] = count, count + 1
        stack[depth, 0], stack[depth, 1], stack[depth, 2] = count + 1, at, e
        stack[depth + 1, 0], stack[depth + 1, 1], stack[depth + 1, 2] = count, s, at
        depth += 2
        count += 2
    return count, n_small
