"""A tree ensemble as plain int/float arrays, with its own inference.

Trees are grown by ``gini_trees`` (the default) or by scikit-learn (``FlatForest.grow``).
Model bundles hold only JSON and numeric arrays (no pickle), so a grown forest is
flattened into one record per node, the trees one after
another (``_packed``: split feature, float32 threshold, children; 16 bytes). A leaf's
record holds its answer: the class of a leaf whose samples are all of one class (every
leaf of a fitted forest, grown until its leaves are pure), or the number of its class
distribution in compressed sparse rows (``mixed_*``: leaves a promotion counted samples
of another class into). Inference is a small compiled walk (numba) over those records,
so predictions do not depend on scikit-learn's private estimator layout and are
bit-identical after a bundle round-trip. The records are what is stored and what the
walk reads: a process holds each node once. Bundles made before 2026-11-26 stored five
arrays per node (24 bytes), a distribution for every leaf (20 bytes a leaf), and the
walk packed a copy of the nodes at load; they are converted at load. Internal nodes'
class counts are not kept (inference never reads them), which keeps a 300-tree forest
on PHAC-2 at a few MB instead of hundreds.

The walk takes a block of samples through one tree at a time: the tree's nodes
stay in cache, and the block's paths are independent chains of loads that the
CPU overlaps. That is 3-4x faster per tree than stepping all (sample, tree) paths
together in numpy, and a single sample takes ~15 us instead of ~300 us
(docs/BENCHMARKS.md).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numba import njit

from app.framework.growing import ByBuffer, appended, with_room
from app.methods.gini_trees import grow_trees
from app.methods.leaf_trees import LeafTree, grow_leaf

_KEYS = ("nodes", "roots", "mixed_ptr", "mixed_class", "mixed_value", "leaf_count")
#: the node arrays of bundles made before the records (``_packed`` makes records of them)
_NODE_KEYS = ("feature", "threshold", "left", "right", "leaf_of_node")
#: the leaf distributions of those bundles, one per leaf (``_split_leaves``)
_LEAF_KEYS = ("leaf_ptr", "leaf_class", "leaf_value")
#: optional state: leaf nodes a promotion replaced, and the nodes appended in their place
#: (``with_samples``); a forest never grown so has none
_FROM, _TO = "redirect_from", "redirect_to"
_NO_REDIRECTS = np.zeros(0, np.int32)  # the walk's ``after`` of a forest without redirects
#: training samples per leaf (weights of ``with_samples``); bundles made before it lack
#: it, and each leaf then counts as one sample
_COUNTS = "leaf_count"


class FlatForest:
    """Class-probability trees (one output) flattened into arrays; see the module docstring."""

    def __init__(
        self,
        arrays: dict[str, np.ndarray],
        n_classes: int,
        n_features: int,
        check: bool = True,
        redirects: _Redirects | None = None,
    ) -> None:
        """``arrays``: the state (``get_state``); the node arrays and leaf distributions of
        a bundle made before the records are converted here. ``check``: validate the
        arrays (a stored forest's); False only for arrays this module has just built (a
        promotion's grown forest: the check reads every node). ``redirects``: where the
        walk goes on from a leaf a promotion replaced, where the caller has them (a
        promotion extends its forest's); otherwise made here from ``redirect_from`` /
        ``redirect_to``."""
        if "nodes" not in arrays and all(k in arrays for k in _NODE_KEYS):
            arrays = {**arrays, "nodes": _packed(arrays)}
        if "mixed_ptr" not in arrays and all(k in arrays for k in (*_LEAF_KEYS, "nodes")):
            arrays = {**arrays, **_split_leaves(arrays)}
        missing = [k for k in _KEYS if k not in arrays]
        if missing:
            raise ValueError(f"forest state lacks {missing}")
        self.nodes = np.asarray(arrays["nodes"], np.int32)
        if self.nodes.ndim != 2 or self.nodes.shape[1] != 4:
            raise ValueError(f"forest node records must be (nodes, 4), not {self.nodes.shape}")
        self.roots = np.asarray(arrays["roots"], np.int32)
        self.mixed_ptr = np.asarray(arrays["mixed_ptr"], np.int64)
        self.mixed_class = np.asarray(arrays["mixed_class"], np.int32)
        self.mixed_value = np.asarray(arrays["mixed_value"], np.float64)
        self.leaf_count = np.asarray(arrays[_COUNTS], np.int32)
        none = np.zeros(0, np.int32)
        self.redirect_from = np.asarray(arrays.get(_FROM, none), np.int32)
        self.redirect_to = np.asarray(arrays.get(_TO, none), np.int32)
        self.n_classes = int(n_classes)
        self.n_features = int(n_features)
        if check:
            self._check()
        if redirects is None:
            redirects = _Redirects(len(self.leaf_count))
            redirects.point(self.nodes[self.redirect_from, 2], self.redirect_to)
        self._redirects = redirects
        # a forest that no promotion grew has no leaf to go on from (a later promotion's
        # replacements lie past its nodes): its walk skips the lookup, a cache miss per
        # tree on a large forest
        self._next = (
            redirects.first(len(self.leaf_count)) if len(self.redirect_from) else _NO_REDIRECTS
        )

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def redirect_nbytes(self) -> int:
        """Bytes of the leaf-redirect buffer this forest holds (``_Redirects``: shared with
        the forests promotions grow from it in place; none until a promotion grows one),
        whether or not its walk reads it."""
        return self._redirects.nbytes

    def leaf_index(self, leaf_nodes: np.ndarray) -> np.ndarray:
        """The leaf ordinals (rows of ``leaf_count``) of leaf nodes."""
        return self.nodes[leaf_nodes, 2]

    def distribution(self, leaf_node: int) -> tuple[np.ndarray, np.ndarray]:
        """(classes, shares) of the samples that reached leaf node ``leaf_node``."""
        answer = int(self.nodes[leaf_node, 3])
        if answer >= 0:
            return np.asarray([answer], np.int32), np.ones(1)
        at = slice(self.mixed_ptr[-1 - answer], self.mixed_ptr[-answer])
        return self.mixed_class[at], self.mixed_value[at]

    def _classes_at(self, leaf_nodes: np.ndarray) -> np.ndarray:
        """Every class that reached any of ``leaf_nodes``."""
        answers = self.nodes[leaf_nodes, 3]
        mixed = -1 - answers[answers < 0]
        starts, ends = self.mixed_ptr[mixed], self.mixed_ptr[mixed + 1]
        sizes = ends - starts
        entries = np.repeat(ends - np.cumsum(sizes), sizes) + np.arange(int(sizes.sum()))
        return np.union1d(answers[answers >= 0], self.mixed_class[entries])

    def _check(self) -> None:
        """Every node record, but those a forest checked before in this process began with
        (``_Checked``): a promoted version that another process built is loaded as the
        version before with records appended, and only those are read."""
        n = len(self.nodes)
        bounds = (len(self.leaf_count), len(self.mixed_ptr) - 1, self.n_classes, self.n_features)
        start = _checked.rows(self.nodes, bounds)
        records = self.nodes[start:]
        feature, left, right = records[:, 0], records[:, 2], records[:, 3]
        if len(self.roots) == 0 or self.roots.min() < 0 or self.roots.max() >= n:
            raise ValueError("forest roots are out of range")
        internal = feature >= 0
        if internal.any():
            kids = np.concatenate([left[internal], right[internal]])
            if kids.min() < 0 or kids.max() >= n or feature[internal].max() >= self.n_features:
                raise ValueError("forest children or split features are out of range")
            # children come after their parent (as scikit-learn numbers them): no cycles,
            # so every walk ends at a leaf
            parents = start + np.flatnonzero(internal)
            if (left[internal] <= parents).any() or (right[internal] <= parents).any():
                raise ValueError("forest children must come after their parent node")
        if (feature[~internal] != -1).any():
            raise ValueError("forest leaf records must have feature -1")
        moved, to = self.redirect_from, self.redirect_to
        if len(moved) != len(to) or (
            len(moved)
            and (
                moved.min() < 0
                or to.max() >= n
                or (to <= moved).any()  # replacements come after: no cycles
                or (self.nodes[moved, 0] >= 0).any()
                or len(np.unique(moved)) != len(moved)
            )
        ):
            raise ValueError("forest redirected leaves are inconsistent")
        leaves, answers = left[~internal], right[~internal]
        if len(leaves) and (leaves.min() < 0 or leaves.max() >= len(self.leaf_count)):
            raise ValueError("forest leaves are out of range")
        if (self.leaf_count < 1).any():
            raise ValueError("forest leaf sample counts must be positive")
        n_mixed = len(self.mixed_ptr) - 1
        if (
            n_mixed < 0
            or len(self.mixed_class) != len(self.mixed_value)
            or self.mixed_ptr[0] != 0
            or self.mixed_ptr[-1] != len(self.mixed_class)
            or (np.diff(self.mixed_ptr) < 0).any()
            or (len(answers) and answers.min() < -n_mixed)
        ):
            raise ValueError("forest leaf distributions are inconsistent")
        if (len(answers) and answers.max() >= self.n_classes) or (
            len(self.mixed_class)
            and (self.mixed_class.min() < 0 or self.mixed_class.max() >= self.n_classes)
        ):
            raise ValueError("forest leaf classes are out of range")
        _checked.add(self.nodes, bounds)

    @property
    def n_trees(self) -> int:
        return len(self.roots)

    # ---------------------------------------------------------------- building
    @classmethod
    def from_sklearn(cls, forest: Any) -> FlatForest:
        """From a fitted single-output tree-ensemble classifier whose ``classes_`` are 0 … K-1."""
        classes = np.asarray(forest.classes_)
        if getattr(forest, "n_outputs_", 1) != 1:
            raise ValueError("only single-output forests can be flattened")
        if not np.array_equal(classes, np.arange(len(classes))):
            raise ValueError("the forest's classes must be 0 … K-1")
        arrays = _ForestArrays()
        for est in forest.estimators_:
            t = est.tree_
            leaf = t.children_left < 0
            values = t.value[leaf, 0, :].astype(np.float64)
            values /= np.maximum(values.sum(axis=1, keepdims=True), 1e-300)
            rows, cols = np.nonzero(values)
            arrays.add(t, rows, cols, values[rows, cols], t.n_node_samples[leaf])
        return cls(arrays.done(), len(classes), int(forest.n_features_in_))

    @classmethod
    def grow(
        cls,
        x: np.ndarray,
        y: np.ndarray,
        n_classes: int,
        n_estimators: int,
        max_features: Any,
        seed: int,
        n_jobs: int | None,
        grower: str = "gini",
        codes: int = 32,
        trees_at_once: int = 10,
    ) -> FlatForest:
        """Extremely randomised trees on samples ``x`` (N, D) of classes ``y`` in 0 … K-1.

        ``grower`` "gini" (the default): ``gini_trees.grow_trees``, compiled, the exact Gini
        criterion at a cost that does not depend on K, ``n_jobs`` trees at a time; each
        leaf then gets the class distribution of the training samples that reach it, kept
        sparsely, so memory is linear in N. ``codes`` and ``trees_at_once`` apply to
        ``grower`` "sklearn" alone, scikit-learn's extra trees, as fitted before 2026-11-27.

        With ``codes`` = 0, scikit-learn's ``ExtraTreesClassifier``: its trees keep a K-wide
        class distribution in every node while they grow, so time and memory grow with N x K
        (12.8 GB of node values alone at 1,000 simulated objects). With ``codes`` = d > 0,
        scikit-learn's ``ExtraTreesRegressor`` grown on a random Gaussian d-dim code per
        class: a node's code variance is, in expectation, its Gini impurity (1 - sum p_k^2
        up to a factor), so splits are chosen as the classifier's are, at a cost that does
        not depend on K; the trees grow until every leaf's codes are equal, i.e. one class.
        Each leaf then gets the class distribution of the training samples that reach it,
        kept sparsely, so memory is linear in N. Trees are grown ``trees_at_once`` at a time
        and flattened, so scikit-learn's node values of only that many trees are held.
        """
        if grower not in ("gini", "sklearn"):
            raise ValueError(f"grower must be 'gini' or 'sklearn', not {grower!r}")
        if grower == "gini":
            arrays = _ForestArrays()
            y = np.asarray(y, np.int64)
            for tree in grow_trees(x, y, n_classes, n_estimators, max_features, seed, n_jobs):
                arrays.add_reached(tree, tree.leaf_of_sample, y, n_classes)
            return cls(arrays.done(), n_classes, x.shape[1])
        from sklearn.ensemble import ExtraTreesClassifier, ExtraTreesRegressor

        if codes == 0:
            et = ExtraTreesClassifier(
                n_estimators=n_estimators,
                max_features=max_features,
                random_state=seed,
                n_jobs=n_jobs,
            ).fit(x, y)
            return cls.from_sklearn(et)
        y = np.asarray(y, np.int64)
        streams = np.random.SeedSequence(seed)
        code_rng, tree_seeds = (
            np.random.default_rng(streams),
            streams.generate_state((n_estimators + trees_at_once - 1) // trees_at_once),
        )
        target = code_rng.standard_normal((n_classes, codes))[y]
        arrays = _ForestArrays()
        for chunk, start in enumerate(range(0, n_estimators, trees_at_once)):
            et = ExtraTreesRegressor(
                n_estimators=min(trees_at_once, n_estimators - start),
                max_features=max_features,
                random_state=int(tree_seeds[chunk]),
                n_jobs=n_jobs,
            ).fit(x, target)
            reached = et.apply(x)  # (N, trees) node each training sample ends in
            for j, est in enumerate(et.estimators_):
                arrays.add_reached(est.tree_, reached[:, j], y, n_classes)
            del et, reached
        return cls(arrays.done(), n_classes, x.shape[1])

    def with_samples(
        self,
        x: np.ndarray,
        y: np.ndarray,
        n_classes: int,
        seen_x: np.ndarray,
        seen_y: np.ndarray,
        max_features: Any,
        seed: int,
    ) -> FlatForest:
        """A forest that has also learnt samples ``x`` (N, D) of classes ``y`` (in 0 …
        ``n_classes``-1, ``n_classes`` at least this forest's), without growing it again.

        ``seen_x``, ``seen_y``: the samples it was grown on (or those it has learnt since);
        ``seen_x`` is anything whose rows ``seen_x[rows]`` gives. In every tree, a leaf that
        the new samples reach is grown further on its own samples, seen and new, by
        extremely randomised tree (``max_features`` as grown, ``leaf_trees.grow_leaf``)
        until its leaves are pure; a leaf that stays one class only counts the new samples.
        Only the seen samples of the classes those leaves hold are taken through the trees
        (a leaf's distribution names every class that reached it). The forest's arrays are
        copied as they are and only appended to (``_Grown``): a reached leaf node is
        redirected to its replacement at the end, so the cost beyond copying does not grow
        with the catalogue, and a store writes only the blocks that were appended.
        The splits above those leaves were chosen without the new samples, so the result
        differs from a forest grown on everything (bounded in tests/methods/test_grow_known.py).
        """
        y, seen_y = np.asarray(y, np.int64), np.asarray(seen_y, np.int64)
        if n_classes < self.n_classes or len(y) != len(x) or len(seen_y) != len(seen_x):
            raise ValueError("with_samples needs one class per sample and no fewer classes")
        if len(y) and (y.min() < 0 or y.max() >= n_classes):
            raise ValueError(f"sample classes must lie in 0 … {n_classes - 1}")
        x = self._inputs(x)
        new_leaf = self.apply(x)  # (N, trees) leaf nodes
        near_rows = np.flatnonzero(np.isin(seen_y, self._classes_at(np.unique(new_leaf))))
        seen_x, seen_y = self._inputs(np.asarray(seen_x[near_rows])), seen_y[near_rows]
        out = _Grown(self)
        rng = np.random.default_rng(seed)
        for t in range(self.n_trees):
            reached = _members(new_leaf[:, t])
            # only the seen samples of the classes these leaves hold can be in them: those
            # go down this tree alone (all of them down every tree cost 0.7 s a forest at
            # 10,000 objects)
            rows = np.flatnonzero(np.isin(seen_y, self._classes_at(np.fromiter(reached, int))))
            column = self._tree_leaves(seen_x[rows], t)
            hit = np.isin(column, list(reached))
            near = rows[hit]
            seen_at = {n: near[i] for n, i in _members(column[hit]).items()}
            for node, members in reached.items():
                here = seen_at.get(node, np.zeros(0, np.int64))
                labels = np.concatenate([seen_y[here], y[members]])
                sub = None
                if len(np.unique(labels)) > 1:
                    local = grow_leaf(
                        np.concatenate([seen_x[here], x[members]]),
                        labels,
                        max_features,
                        int(rng.integers(2**31)),
                    )
                    sub = local if local.node_count > 1 else None
                if sub is None:  # one class, or no split separates them: count them in
                    out.count_in(node, *np.unique(y[members], return_counts=True))
                else:
                    out.graft(node, sub)
        return out.done(n_classes)

    # --------------------------------------------------------------- inference
    def _inputs(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, np.float32)  # scikit-learn compares float32 inputs
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(f"expected inputs of shape (N, {self.n_features}), got {x.shape}")
        return x

    def apply(self, x: np.ndarray) -> np.ndarray:
        """(N, n_trees) global node index of the leaf each sample reaches in each tree."""
        x = self._inputs(x)
        out = np.empty((len(x), self.n_trees), np.int32)
        self._walk(x, leaves=out)
        return out

    def _tree_leaves(self, x: np.ndarray, t: int) -> np.ndarray:
        """(N,) the leaf node float32 samples ``x`` reach in tree ``t``."""
        out = np.empty((len(x), 1), np.int32)
        self._walk(x, leaves=out, trees=slice(t, t + 1))
        return out[:, 0]

    def walk_arrays(self) -> tuple[np.ndarray, ...]:
        """What the compiled walk takes, for a caller that walks the trees itself: the node
        records (``_packed``), where a walk goes on from each leaf (``_Redirects``; empty
        for a forest without replaced leaves),
        ``roots``, ``mixed_ptr``, ``mixed_class``, ``mixed_value``. Read, never written."""
        return (
            self.nodes,
            self._next,
            self.roots,
            self.mixed_ptr,
            self.mixed_class,
            self.mixed_value,
        )

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(N, K) mean over trees of the reached leaf's class distribution."""
        x = self._inputs(x)
        out = np.zeros((len(x), self.n_classes), np.float64)
        self._walk(x, proba=out)
        out /= self.n_trees
        return out

    def _walk(
        self,
        x: np.ndarray,
        leaves: np.ndarray | None = None,
        proba: np.ndarray | None = None,
        trees: slice = slice(None),
    ) -> None:
        none = np.zeros((0, 0), np.int32)
        _walk(
            x,
            self.nodes,
            self.nodes.view(np.float32),
            self._next,
            self.roots[trees],
            self.mixed_ptr,
            self.mixed_class,
            self.mixed_value,
            none if leaves is None else leaves,
            none.astype(np.float64) if proba is None else proba,
        )

    # ------------------------------------------------------------ persistence
    def get_state(self) -> dict[str, np.ndarray]:
        out = {k: getattr(self, k) for k in _KEYS}
        if len(self.redirect_from):
            out.update({_FROM: self.redirect_from, _TO: self.redirect_to})
        return out

    @classmethod
    def from_state(
        cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int
    ) -> FlatForest:
        return cls(arrays, n_classes, n_features)

    def __deepcopy__(self, memo: dict) -> FlatForest:
        # Immutable after construction: recognizers copied by enrolment share it.
        return self


class _ForestArrays:
    """Node records and leaf distributions of trees flattened one after another
    (``FlatForest``'s state)."""

    def __init__(self) -> None:
        self.parts: dict[str, list[np.ndarray]] = {
            k: [] for k in ("nodes", "roots", "mixed_class", "mixed_value", _COUNTS)
        }
        self.mixed_sizes: list[np.ndarray] = []
        self.offset = self.n_leaves = self.n_mixed = 0

    def add(
        self,
        tree: Any,
        rows: np.ndarray,
        cols: np.ndarray,
        values: np.ndarray,
        leaf_count: np.ndarray,
    ) -> None:
        """A scikit-learn ``tree_`` and its leaves' class distributions: nonzero entries
        (leaf ordinal ``rows``, class ``cols``, ``values``), ordered by leaf then class, and
        the training samples that reach each leaf."""
        n, off = tree.node_count, self.offset
        is_leaf = tree.children_left < 0
        leaves = int(is_leaf.sum())
        answers, sizes, mixed_class, mixed_value = _answers(
            rows, cols, values, leaves, self.n_mixed
        )
        records = _tree_records(tree, off, self.n_leaves)
        records[is_leaf, 3] = answers
        p = self.parts
        p["nodes"].append(records)
        p["roots"].append(np.asarray([off], np.int32))
        p["mixed_class"].append(mixed_class.astype(np.int32))
        p["mixed_value"].append(mixed_value.astype(np.float64))
        p[_COUNTS].append(np.maximum(np.asarray(leaf_count), 1).astype(np.int32))
        self.mixed_sizes.append(sizes)
        self.offset += n
        self.n_leaves += leaves
        self.n_mixed += len(sizes)

    def add_reached(self, tree: Any, reached: np.ndarray, y: np.ndarray, n_classes: int) -> None:
        """A grown tree whose training samples, of classes ``y``, ended in nodes
        ``reached``: each leaf gets the class shares of the samples that reached it."""
        leaf_number = np.cumsum(tree.children_left < 0) - 1  # node -> its leaf's ordinal
        reached_leaf = leaf_number[reached]
        rows, cols, values = _leaf_distributions(reached_leaf, y, n_classes)
        n_leaves = int(leaf_number[-1]) + 1
        self.add(tree, rows, cols, values, np.bincount(reached_leaf, minlength=n_leaves))

    def done(self) -> dict[str, np.ndarray]:
        # with room behind them: a promotion appends to them without copying (``_Grown``)
        out = {k: with_room(*v) for k, v in self.parts.items()}
        sizes = np.concatenate([np.zeros(0, np.int64), *self.mixed_sizes])
        out["mixed_ptr"] = with_room(np.r_[0, np.cumsum(sizes)].astype(np.int64))
        return out


def _answers(
    rows: np.ndarray, cols: np.ndarray, values: np.ndarray, n_leaves: int, first_mixed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What the records of ``n_leaves`` leaves answer, given their distributions' entries
    (leaf ``rows`` in 0 … n_leaves-1, ordered by leaf, ``cols``, ``values``): a leaf whose
    one entry holds all its mass answers that class; any other leaf answers -1 - m, m its
    number among the mixed distributions, numbered from ``first_mixed``. Returns the
    answers and the mixed distributions' sizes, classes and values."""
    sizes = np.bincount(rows, minlength=n_leaves)
    starts = np.cumsum(sizes) - sizes
    single = sizes == 1
    single[single] = values[starts[single]] == 1.0
    answers = np.empty(n_leaves, np.int32)
    answers[single] = cols[starts[single]]
    mixed = np.flatnonzero(~single)
    answers[mixed] = -1 - (first_mixed + np.arange(len(mixed)))
    kept = ~single[rows]
    return answers, sizes[mixed], cols[kept], values[kept]


def _split_leaves(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The answers of a bundle made before the records' leaf answers: its one distribution
    per leaf (``leaf_ptr``, ``leaf_class``, ``leaf_value``) as answers written into a copy
    of its records, and the mixed distributions; one sample per leaf where it has no
    ``leaf_count``."""
    ptr = np.asarray(arrays["leaf_ptr"], np.int64)
    classes = np.asarray(arrays["leaf_class"], np.int32)
    values = np.asarray(arrays["leaf_value"], np.float64)
    nodes = np.array(arrays["nodes"], np.int32)  # a copy: the answers are written into it
    if (
        ptr.ndim != 1
        or len(ptr) < 2
        or ptr[0] != 0
        or ptr[-1] != len(classes)
        or len(classes) != len(values)
        or (np.diff(ptr) < 0).any()
    ):
        raise ValueError("forest leaf distributions are inconsistent")
    if nodes.ndim != 2 or nodes.shape[1] != 4:
        raise ValueError(f"forest node records must be (nodes, 4), not {nodes.shape}")
    n_leaves = len(ptr) - 1
    rows = np.repeat(np.arange(n_leaves), np.diff(ptr))
    answers, sizes, mixed_class, mixed_value = _answers(rows, classes, values, n_leaves, 0)
    leaf = np.flatnonzero(nodes[:, 0] < 0)
    ordinals = nodes[leaf, 2]
    if len(leaf) and (ordinals.min() < 0 or ordinals.max() >= n_leaves):
        raise ValueError("forest leaves are out of range")
    nodes[leaf, 3] = answers[ordinals]
    out = {
        "nodes": nodes,
        "mixed_ptr": np.r_[0, np.cumsum(sizes)].astype(np.int64),
        "mixed_class": mixed_class,
        "mixed_value": mixed_value,
    }
    if _COUNTS not in arrays:
        out[_COUNTS] = np.ones(n_leaves, np.int32)
    return out


def _tree_records(tree: Any, first_node: int, first_leaf: int) -> np.ndarray:
    """The records (``_packed``) of a scikit-learn ``tree_`` (or a ``LeafTree``) whose
    nodes are numbered from ``first_node`` and whose leaves from ``first_leaf``."""
    is_leaf = tree.children_left < 0
    leaf_ids = np.full(tree.node_count, -1, np.int64)
    leaf_ids[is_leaf] = first_leaf + np.arange(int(is_leaf.sum()))
    return _packed(
        {
            "feature": np.where(is_leaf, -1, tree.feature),
            "threshold": tree.threshold,
            "left": np.where(is_leaf, -1, tree.children_left + first_node),
            "right": np.where(is_leaf, -1, tree.children_right + first_node),
            "leaf_of_node": leaf_ids,
        }
    )


class _Grown:
    """The arrays of a forest whose reached leaves ``with_samples`` grew, append-only: the
    forest's own arrays are copied unchanged (a store keeps their blocks as they were, and
    only the new ones are written), and each reached leaf node is redirected to what
    replaces it, appended at the end: the root of the subtree grown on it, or a leaf node
    whose distribution has the new samples counted in. A walk that reaches a redirected
    leaf goes on from its replacement (``redirect_from`` / ``redirect_to``)."""

    def __init__(self, forest: FlatForest) -> None:
        self.forest = forest
        self.n_nodes, self.n_leaves = forest.n_nodes, len(forest.leaf_count)
        self.nodes: list[np.ndarray] = []  # the new nodes' records
        self.moved: list[tuple[int, int]] = []  # (reached leaf node, the node replacing it)
        # the new leaves' entries (leaf, class, samples) and sample counts
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.mass: list[np.ndarray] = []
        self.counts: list[np.ndarray] = []

    def graft(self, node: int, sub: LeafTree) -> None:
        """Leaf ``node`` replaced by tree ``sub`` grown on its samples."""
        is_leaf = sub.children_left < 0
        value = sub.value[is_leaf]
        lr, lc = np.nonzero(value)
        share = value[lr, lc] / value[lr].sum(axis=1)
        n_here = sub.n_node_samples[is_leaf]
        self._append(
            node,
            _tree_records(sub, self.n_nodes, self.n_leaves),
            self.n_leaves + lr,
            sub.classes[lc],
            share * n_here[lr],
            n_here,
        )

    def count_in(self, node: int, classes: np.ndarray, samples: np.ndarray) -> None:
        """Leaf ``node`` replaced by a leaf that has also counted ``samples`` of ``classes``:
        its entries again, the old ones as value x samples, then the new samples."""
        f = self.forest
        leaf = int(f.nodes[node, 2])
        old_classes, old_shares = f.distribution(node)
        cols = np.concatenate([old_classes, classes])
        self._append(
            node,
            np.asarray([[-1, f.nodes[node, 1], self.n_leaves, -1]], np.int32),
            np.full(len(cols), self.n_leaves),
            cols,
            np.concatenate([old_shares * f.leaf_count[leaf], samples.astype(np.float64)]),
            [int(f.leaf_count[leaf]) + int(samples.sum())],
        )

    def _append(self, node, records, rows, cols, mass, counts) -> None:
        self.moved.append((node, self.n_nodes))
        self.nodes.append(records)
        self.rows.append(rows)
        self.cols.append(cols)
        self.mass.append(mass)
        self.counts.append(np.asarray(counts, np.int64))
        self.n_nodes += len(records)
        self.n_leaves += len(counts)

    def done(self, n_classes: int) -> FlatForest:
        f = self.forest
        lr, lc, lv = _leaf_distributions(
            np.concatenate([np.zeros(0, np.int64), *self.rows]),
            np.concatenate([np.zeros(0, np.int64), *self.cols]),
            n_classes,
            np.concatenate([np.zeros(0), *self.mass]),
        )
        n_old = len(f.leaf_count)
        answers, sizes, mixed_class, mixed_value = _answers(
            lr - n_old, lc, lv, self.n_leaves - n_old, len(f.mixed_ptr) - 1
        )
        new = np.concatenate([np.zeros((0, 4), np.int32), *self.nodes])
        leaf = new[:, 0] < 0
        new[leaf, 3] = answers[new[leaf, 2] - n_old]
        moved = np.asarray(self.moved, np.int32).reshape(-1, 2)
        arrays = {
            "nodes": appended(f.nodes, new),
            "roots": f.roots,
            "mixed_ptr": appended(f.mixed_ptr, f.mixed_ptr[-1] + np.cumsum(sizes)),
            "mixed_class": appended(f.mixed_class, mixed_class),
            "mixed_value": appended(f.mixed_value, mixed_value),
            _COUNTS: appended(f.leaf_count, *self.counts),
            _FROM: appended(f.redirect_from, moved[:, 0]),
            _TO: appended(f.redirect_to, moved[:, 1]),
        }
        redirects = f._redirects.grown(n_old, self.n_leaves, f.n_nodes)
        redirects.point(f.leaf_index(moved[:, 0]), moved[:, 1])
        return FlatForest(arrays, n_classes, f.n_features, check=False, redirects=redirects)


class _Checked:
    """Node records checked in this process, by the buffer they begin (``ByBuffer``): how
    many rows, against which bounds (leaves, mixed distributions, classes, features).
    Bounds only grow, so rows checked once stay valid for a forest that begins with them
    within larger bounds. The check read every node: 7 s at 10,000 objects for the process
    that loads a promoted version another process built."""

    def __init__(self) -> None:
        self._done = ByBuffer()

    def rows(self, records: np.ndarray, bounds: tuple[int, ...]) -> int:
        """Rows from the first of ``records`` known to be valid within ``bounds``."""
        found = self._done.get(records)
        if found is None:
            return 0
        rows, checked = found
        grown = all(a <= b for a, b in zip(checked, bounds, strict=True))
        return rows if rows <= len(records) and grown and checked[3] == bounds[3] else 0

    def add(self, records: np.ndarray, bounds: tuple[int, ...]) -> None:
        self._done.put(records, (len(records), bounds))


_checked = _Checked()


class _Redirects:
    """Where a walk goes on from each leaf of a forest and of the forests promotions grew
    from it: the node that replaced the leaf, or -1 (one int32 per leaf, made from
    ``redirect_from`` / ``redirect_to``, never stored), in one buffer with spare rows. A
    promotion points the leaves it replaced at their replacements in place, and a forest
    follows a leaf's replacement only to a node among its own, so it sees no later
    promotion's: the forest before a promotion answers as it did while and after the
    promotion is built, and the node records themselves are never written.

    The buffer is made at the first redirect: a forest no promotion grew never reads it
    (its walk skips the lookup), and every process that loads a model holds its forests
    (1.25 x 4 bytes a leaf, tens of MB a forest at 10,000 objects)."""

    def __init__(self, n_leaves: int, first: np.ndarray | None = None) -> None:
        """For ``n_leaves`` leaves, the first as ``first`` says if given, the rest -1."""
        self._n_leaves = n_leaves
        self._buffer: np.ndarray | None = None
        self._filled = n_leaves
        self._lock = threading.Lock()
        if first is not None:
            self._made()[: len(first)] = first

    def _made(self) -> np.ndarray:
        with self._lock:
            if self._buffer is None:
                n = self._n_leaves
                self._buffer = np.full(n + n // 4 + 1, -1, np.int32)
            return self._buffer

    @property
    def nbytes(self) -> int:
        return 0 if self._buffer is None else self._buffer.nbytes

    def first(self, n_leaves: int) -> np.ndarray:
        """Those of a forest of ``n_leaves`` leaves, read-only."""
        view = self._made()[:n_leaves]
        view.flags.writeable = False
        return view

    def point(self, leaves: np.ndarray, to: np.ndarray) -> None:
        if len(leaves):
            self._made()[leaves] = to  # 4-byte stores: a walk reads the old or the new

    def grown(self, n_old: int, n_leaves: int, n_old_nodes: int) -> _Redirects:
        """For a forest grown from one of ``n_old`` leaves and ``n_old_nodes`` nodes to
        ``n_leaves`` leaves: these, when no forest has grown from those first leaves yet
        and the spare rows suffice, else a copy of the first ``n_old``."""
        buffer = self._made()
        with self._lock:
            in_place = self._filled == n_old and n_leaves <= len(buffer)
            if in_place:
                self._filled = n_leaves  # a second promotion of the same forest copies
        if in_place:
            return self
        first = buffer[:n_old].copy()
        first[first >= n_old_nodes] = -1  # a sibling promotion's, which these are not
        return _Redirects(n_leaves, first)


def _packed(nodes: dict[str, np.ndarray]) -> np.ndarray:
    """The node records of node arrays (``feature``, float64 ``threshold``, ``left``,
    ``right``, ``leaf_of_node``; -1 where a node has none): one 16-byte record per node,
    so a step touches one cache line (split feature, float32 threshold bits, left and
    right child; a leaf, feature -1, keeps its leaf index where the left child would be,
    and -1 where the right child would be, for its answer: ``_answers``). For a float32
    x, x <= t (float64) exactly when x <= the largest float32 <= t, so the walk compares
    in float32 (half the memory traffic) with the same outcome."""
    feature, threshold = np.asarray(nodes["feature"]), np.asarray(nodes["threshold"])
    t32 = threshold.astype(np.float32)
    above = t32.astype(np.float64) > threshold
    t32[above] = np.nextafter(t32[above], np.float32(-np.inf))
    leaf = feature < 0
    out = np.empty((len(feature), 4), np.int32)
    out[:, 0] = feature
    out[:, 1] = t32.view(np.int32)
    out[:, 2] = np.where(leaf, nodes["leaf_of_node"], nodes["left"])
    out[:, 3] = np.where(leaf, -1, nodes["right"])
    return out


def _members(nodes: np.ndarray) -> dict[int, np.ndarray]:
    """Node -> the row indices of ``nodes`` that hold it."""
    order = np.argsort(nodes, kind="stable")
    found, starts = np.unique(nodes[order], return_index=True)
    return {int(n): part for n, part in zip(found, np.split(order, starts[1:]), strict=True)}


def _leaf_distributions(
    leaf: np.ndarray, y: np.ndarray, n_classes: int, mass: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(leaf, class, share) of the classes of the samples reaching each leaf, sparse and
    ordered by leaf then class: one pass over the samples, whatever the number of classes.
    ``mass``: what each (leaf, class) entry weighs (default: one sample each); entries of
    the same pair add up."""
    pairs, at = np.unique(leaf.astype(np.int64) * n_classes + y, return_inverse=True)
    weight = np.bincount(at.ravel(), weights=mass, minlength=len(pairs))
    rows, cols = np.divmod(pairs, n_classes)
    totals = np.bincount(rows, weights=weight)
    return rows, cols, weight / totals[rows]


# ---------------------------------------------------------------- compiled walk
_BLOCK = 8  # samples taken through a tree together (independent load chains)


@njit(cache=True, nogil=True)
def _descend(x, rows, nodes, thresholds, after, at, n):
    """Chains k < n, each sample ``x[rows[k]]`` from node ``at[k]``, down to their leaf
    nodes (into ``at``), a step of every chain at a time: independent load chains.
    ``after``: per leaf, the node a promotion replaced it with, or -1; empty where the
    forest has no replaced leaf."""
    descending = True
    while descending:
        descending = False
        for k in range(n):
            node = at[k]
            f = nodes[node, 0]
            if f >= 0:
                at[k] = nodes[node, 2 + (x[rows[k], f] > thresholds[node, 1])]
                descending = True
            elif after.shape[0] > 0 and 0 <= after[nodes[node, 2]] < nodes.shape[0]:
                # a leaf a promotion of this forest replaced: on from its replacement (a
                # later promotion's, past this forest's nodes, is not this forest's)
                at[k] = after[nodes[node, 2]]
                descending = True


@njit(cache=True, nogil=True)
def _reached(i, t, node, nodes, mixed_ptr, mixed_class, mixed_value, leaves, proba):
    """Sample i reached leaf ``node`` in tree t: into ``leaves`` and/or ``proba``."""
    if leaves.shape[0] > 0:
        leaves[i, t] = node
    if proba.shape[0] > 0:
        answer = nodes[node, 3]
        if answer >= 0:  # all of the leaf's samples are of one class
            proba[i, answer] += 1.0
        else:
            m = -1 - answer
            for j in range(mixed_ptr[m], mixed_ptr[m + 1]):
                proba[i, mixed_class[j]] += mixed_value[j]


@njit(cache=True, nogil=True)
def walk_trees(
    x, i, nodes, thresholds, after, roots, mixed_ptr, mixed_class, mixed_value, leaves, proba
):
    """``_walk`` of sample i alone: _BLOCK trees taken down together (a single sample has
    one path per tree, so a block of samples gives it no independent chains), their leaves
    then added in tree order, so the sums have the same bits as ``_walk``'s."""
    at = np.empty(_BLOCK, np.int32)
    rows = np.full(_BLOCK, i, np.int64)
    for lo in range(0, roots.shape[0], _BLOCK):
        hi = min(lo + _BLOCK, roots.shape[0])
        at[: hi - lo] = roots[lo:hi]
        _descend(x, rows, nodes, thresholds, after, at, hi - lo)
        for k in range(hi - lo):
            _reached(i, lo + k, at[k], nodes, mixed_ptr, mixed_class, mixed_value, leaves, proba)


@njit(cache=True, nogil=True)
def _walk(x, nodes, thresholds, after, roots, mixed_ptr, mixed_class, mixed_value, leaves, proba):
    """Every sample through every tree: the leaf node reached into ``leaves`` (N, T) and/or
    the leaf distributions summed into ``proba`` (N, K); an empty array skips that output.
    Sums go tree by tree in tree order (the same bits on every call and after a bundle
    round-trip). _BLOCK samples go down a tree together; fewer take trees in blocks."""
    if x.shape[0] < _BLOCK:
        for i in range(x.shape[0]):
            walk_trees(
                x,
                i,
                nodes,
                thresholds,
                after,
                roots,
                mixed_ptr,
                mixed_class,
                mixed_value,
                leaves,
                proba,
            )
        return
    at = np.empty(_BLOCK, np.int32)
    rows = np.empty(_BLOCK, np.int64)
    for lo in range(0, x.shape[0], _BLOCK):
        hi = min(lo + _BLOCK, x.shape[0])
        for t in range(roots.shape[0]):
            for k in range(hi - lo):
                at[k], rows[k] = roots[t], lo + k
            _descend(x, rows, nodes, thresholds, after, at, hi - lo)
            for k in range(hi - lo):
                _reached(
                    lo + k, t, at[k], nodes, mixed_ptr, mixed_class, mixed_value, leaves, proba
                )
