"""A fitted scikit-learn tree ensemble as plain int/float arrays, with its own inference.

Model bundles hold only JSON and numeric arrays (no pickle), so a fitted
``ExtraTreesClassifier`` is flattened into concatenated node arrays (split
feature, threshold, children) and its leaves' class distributions in compressed
sparse rows. Inference is a small compiled walk (numba) over those arrays, so
predictions do not depend on scikit-learn's private estimator layout and are
bit-identical after a bundle round-trip. Internal nodes' class counts are not kept
(inference never reads them), which keeps a 300-tree forest on PHAC-2 at a few MB
instead of hundreds.

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

from app.framework.growing import appended, with_room

_KEYS = (
    "feature",
    "threshold",
    "left",
    "right",
    "roots",
    "leaf_of_node",
    "leaf_ptr",
    "leaf_class",
    "leaf_value",
)
_NODE_KEYS = ("feature", "threshold", "left", "right", "leaf_of_node")
#: optional state: leaf nodes a promotion replaced, and the nodes appended in their place
#: (``with_samples``); a forest never grown so has none
_FROM, _TO = "redirect_from", "redirect_to"
#: optional state: training samples per leaf (weights of ``with_samples``); bundles made
#: before it lack it, and each leaf then counts as one sample
_COUNTS = "leaf_count"


class FlatForest:
    """Class-probability trees (one output) flattened into arrays; see the module docstring."""

    def __init__(
        self,
        arrays: dict[str, np.ndarray],
        n_classes: int,
        n_features: int,
        check: bool = True,
        records: _WalkRecords | None = None,
    ) -> None:
        """``check``: validate the arrays (a stored forest's); False only for arrays this
        module has just built (a promotion's grown forest: the check reads every node).
        ``records``: the walk's node records of these arrays where the caller has them (a
        promotion extends its forest's); otherwise they are packed here, so that loading a
        model, not the first answer or enrolment after it, pays for that (seconds at
        10,000 objects)."""
        missing = [k for k in _KEYS if k not in arrays]
        if missing:
            raise ValueError(f"forest state lacks {missing}")
        self.feature = np.asarray(arrays["feature"], np.int32)
        self.threshold = np.asarray(arrays["threshold"], np.float64)
        self.left = np.asarray(arrays["left"], np.int32)
        self.right = np.asarray(arrays["right"], np.int32)
        self.roots = np.asarray(arrays["roots"], np.int32)
        self.leaf_of_node = np.asarray(arrays["leaf_of_node"], np.int32)
        self.leaf_ptr = np.asarray(arrays["leaf_ptr"], np.int64)
        self.leaf_class = np.asarray(arrays["leaf_class"], np.int32)
        self.leaf_value = np.asarray(arrays["leaf_value"], np.float64)
        n_leaves = len(self.leaf_ptr) - 1
        counts = arrays.get(_COUNTS)
        self.leaf_count = (
            np.ones(n_leaves, np.int32) if counts is None else np.asarray(counts, np.int32)
        )
        none = np.zeros(0, np.int32)
        self.redirect_from = np.asarray(arrays.get(_FROM, none), np.int32)
        self.redirect_to = np.asarray(arrays.get(_TO, none), np.int32)
        self.n_classes = int(n_classes)
        self.n_features = int(n_features)
        if check:
            self._check()
        if records is None:
            records = _WalkRecords({k: getattr(self, k) for k in _NODE_KEYS})
            records.redirect(self.redirect_from, self.redirect_to)
        self._records = records
        self._nodes = records.first(len(self.feature))

    def _check(self) -> None:
        n = len(self.feature)
        if not (
            len(self.threshold) == len(self.left) == len(self.right) == len(self.leaf_of_node) == n
        ):
            raise ValueError("forest node arrays differ in length")
        if len(self.roots) == 0 or self.roots.min() < 0 or self.roots.max() >= n:
            raise ValueError("forest roots are out of range")
        internal = self.feature >= 0
        if internal.any():
            kids = np.concatenate([self.left[internal], self.right[internal]])
            if kids.min() < 0 or kids.max() >= n or self.feature[internal].max() >= self.n_features:
                raise ValueError("forest children or split features are out of range")
            # children come after their parent (as scikit-learn numbers them): no cycles,
            # so every walk ends at a leaf
            parents = np.flatnonzero(internal)
            if (self.left[parents] <= parents).any() or (self.right[parents] <= parents).any():
                raise ValueError("forest children must come after their parent node")
        moved, to = self.redirect_from, self.redirect_to
        if len(moved) != len(to) or (
            len(moved)
            and (
                moved.min() < 0
                or to.max() >= n
                or (to <= moved).any()  # replacements come after: no cycles
                or internal[moved].any()
                or len(np.unique(moved)) != len(moved)
            )
        ):
            raise ValueError("forest redirected leaves are inconsistent")
        leaves = self.leaf_of_node[~internal]
        if leaves.min() < 0 or leaves.max() + 1 >= len(self.leaf_ptr):
            raise ValueError("forest leaves are out of range")
        if (
            len(self.leaf_class) != len(self.leaf_value)
            or self.leaf_ptr[0] != 0
            or self.leaf_ptr[-1] != len(self.leaf_class)
            or (np.diff(self.leaf_ptr) < 0).any()
        ):
            raise ValueError("forest leaf distributions are inconsistent")
        if self.leaf_count.shape != (len(self.leaf_ptr) - 1,) or (self.leaf_count < 1).any():
            raise ValueError("forest leaf sample counts do not match its leaves")
        if len(self.leaf_class) and (
            self.leaf_class.min() < 0 or self.leaf_class.max() >= self.n_classes
        ):
            raise ValueError("forest leaf classes are out of range")

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
        codes: int,
        trees_at_once: int = 10,
    ) -> FlatForest:
        """Extremely randomised trees on samples ``x`` (N, D) of classes ``y`` in 0 … K-1.

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
                t = est.tree_
                leaf_number = np.cumsum(t.children_left < 0) - 1  # node -> its leaf's ordinal
                reached_leaf = leaf_number[reached[:, j]]
                rows, cols, values = _leaf_distributions(reached_leaf, y, n_classes)
                n_leaves = int(leaf_number[-1]) + 1
                arrays.add(t, rows, cols, values, np.bincount(reached_leaf, minlength=n_leaves))
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
        scikit-learn's ``ExtraTreeClassifier`` (``max_features`` as grown, ``grow_leaf``)
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
        leaves = self.leaf_of_node[np.unique(new_leaf)]
        near_rows = np.flatnonzero(np.isin(seen_y, self.leaf_class[self._entries(leaves)]))
        seen_x, seen_y = self._inputs(np.asarray(seen_x[near_rows])), seen_y[near_rows]
        seen_leaf = self.apply(seen_x)
        out = _Grown(self)
        rng = np.random.default_rng(seed)
        for t in range(self.n_trees):
            reached = _members(new_leaf[:, t])
            column = seen_leaf[:, t]
            near = np.flatnonzero(np.isin(column, list(reached)))
            seen_at = {n: near[i] for n, i in _members(column[near]).items()}
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
                    sub = local if local.tree_.node_count > 1 else None
                if sub is None:  # one class, or no split separates them: count them in
                    out.count_in(node, *np.unique(y[members], return_counts=True))
                else:
                    out.graft(node, sub)
        return out.done(n_classes)

    def _entries(self, leaves: np.ndarray) -> np.ndarray:
        """Indices into ``leaf_class`` / ``leaf_value`` of the entries of ``leaves``."""
        starts, ends = self.leaf_ptr[leaves], self.leaf_ptr[leaves + 1]
        sizes = ends - starts
        return np.repeat(ends - np.cumsum(sizes), sizes) + np.arange(int(sizes.sum()))

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

    def walk_arrays(self) -> tuple[np.ndarray, ...]:
        """What the compiled walk takes, for a caller that walks the trees itself: the packed
        node records (feature, float32 threshold bits, left, right),
        ``roots``, ``leaf_ptr``, ``leaf_class``, ``leaf_value``. Read, never written."""
        return self._nodes, self.roots, self.leaf_ptr, self.leaf_class, self.leaf_value

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(N, K) mean over trees of the reached leaf's class distribution."""
        x = self._inputs(x)
        out = np.zeros((len(x), self.n_classes), np.float64)
        self._walk(x, proba=out)
        out /= self.n_trees
        return out

    def _walk(
        self, x: np.ndarray, leaves: np.ndarray | None = None, proba: np.ndarray | None = None
    ) -> None:
        none = np.zeros((0, 0), np.int32)
        _walk(
            x,
            self._nodes,
            self._nodes.view(np.float32),
            self.roots,
            self.leaf_ptr,
            self.leaf_class,
            self.leaf_value,
            none if leaves is None else leaves,
            none.astype(np.float64) if proba is None else proba,
        )

    # ------------------------------------------------------------ persistence
    def get_state(self) -> dict[str, np.ndarray]:
        out = {**{k: getattr(self, k) for k in _KEYS}, _COUNTS: self.leaf_count}
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
    """Node and leaf arrays of trees flattened one after another (``FlatForest``'s state)."""

    def __init__(self) -> None:
        self.parts: dict[str, list[np.ndarray]] = {
            k: [] for k in (*_KEYS, _COUNTS) if k != "leaf_ptr"
        }
        self.counts: list[np.ndarray] = []
        self.offset = self.n_leaves = 0

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
        p = self.parts
        p["feature"].append(np.where(is_leaf, -1, tree.feature).astype(np.int32))
        p["threshold"].append(tree.threshold.astype(np.float64))
        p["left"].append(np.where(is_leaf, -1, tree.children_left + off).astype(np.int32))
        p["right"].append(np.where(is_leaf, -1, tree.children_right + off).astype(np.int32))
        p["roots"].append(np.asarray([off], np.int32))
        ids = np.full(n, -1, np.int32)
        ids[is_leaf] = self.n_leaves + np.arange(leaves, dtype=np.int32)
        p["leaf_of_node"].append(ids)
        p["leaf_class"].append(np.asarray(cols, np.int32))
        p["leaf_value"].append(np.asarray(values, np.float64))
        p[_COUNTS].append(np.maximum(np.asarray(leaf_count), 1).astype(np.int32))
        self.counts.append(np.bincount(rows, minlength=leaves))
        self.offset += n
        self.n_leaves += leaves

    def done(self) -> dict[str, np.ndarray]:
        # with room behind them: a promotion appends to them without copying (``_Grown``)
        out = {k: with_room(*v) for k, v in self.parts.items()}
        out["leaf_ptr"] = with_room(
            np.r_[0, np.cumsum(np.concatenate(self.counts))].astype(np.int64)
        )
        return out


class _Grown:
    """The arrays of a forest whose reached leaves ``with_samples`` grew, append-only: the
    forest's own arrays are copied unchanged (a store keeps their blocks as they were, and
    only the new ones are written), and each reached leaf node is redirected to what
    replaces it, appended at the end: the root of the subtree grown on it, or a leaf node
    whose distribution has the new samples counted in. A walk that reaches a redirected
    leaf goes on from its replacement (``redirect_from`` / ``redirect_to``)."""

    def __init__(self, forest: FlatForest) -> None:
        self.forest = forest
        self.n_nodes, self.n_leaves = len(forest.feature), len(forest.leaf_count)
        self.nodes: dict[str, list[np.ndarray]] = {k: [] for k in _NODE_KEYS}
        self.moved: list[tuple[int, int]] = []  # (reached leaf node, the node replacing it)
        # the new leaves' entries (leaf, class, samples) and sample counts
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.mass: list[np.ndarray] = []
        self.counts: list[np.ndarray] = []

    def graft(self, node: int, local: Any) -> None:
        """Leaf ``node`` replaced by fitted tree ``local``."""
        sub = local.tree_
        is_leaf = sub.children_left < 0
        glob = self.n_nodes + np.arange(sub.node_count)
        leaf_ids = np.full(sub.node_count, -1, np.int64)
        leaf_ids[is_leaf] = self.n_leaves + np.arange(int(is_leaf.sum()))
        value = sub.value[is_leaf, 0, :]
        lr, lc = np.nonzero(value)
        share = value[lr, lc] / value[lr].sum(axis=1)
        n_here = sub.n_node_samples[is_leaf]
        self._append(
            node,
            (
                np.where(is_leaf, -1, sub.feature),
                sub.threshold,
                np.where(is_leaf, -1, glob[np.maximum(sub.children_left, 0)]),
                np.where(is_leaf, -1, glob[np.maximum(sub.children_right, 0)]),
                leaf_ids,
            ),
            self.n_leaves + lr,
            local.classes_[lc],
            share * n_here[lr],
            n_here,
        )

    def count_in(self, node: int, classes: np.ndarray, samples: np.ndarray) -> None:
        """Leaf ``node`` replaced by a leaf that has also counted ``samples`` of ``classes``:
        its entries again, the old ones as value x samples, then the new samples."""
        f = self.forest
        leaf = int(f.leaf_of_node[node])
        old = slice(f.leaf_ptr[leaf], f.leaf_ptr[leaf + 1])
        cols = np.concatenate([f.leaf_class[old], classes])
        self._append(
            node,
            ([-1], [f.threshold[node]], [-1], [-1], [self.n_leaves]),
            np.full(len(cols), self.n_leaves),
            cols,
            np.concatenate([f.leaf_value[old] * f.leaf_count[leaf], samples.astype(np.float64)]),
            [int(f.leaf_count[leaf]) + int(samples.sum())],
        )

    def _append(self, node, nodes, rows, cols, mass, counts) -> None:
        self.moved.append((node, self.n_nodes))
        for key, part in zip(_NODE_KEYS, nodes, strict=True):
            self.nodes[key].append(np.asarray(part).astype(getattr(self.forest, key).dtype))
        self.rows.append(rows)
        self.cols.append(cols)
        self.mass.append(mass)
        self.counts.append(np.asarray(counts, np.int64))
        self.n_nodes += len(nodes[0])
        self.n_leaves += len(counts)

    def done(self, n_classes: int) -> FlatForest:
        f = self.forest
        n_old_nodes = len(f.feature)
        nodes = {k: appended(getattr(f, k), *self.nodes[k]) for k in _NODE_KEYS}
        lr, lc, lv = _leaf_distributions(
            np.concatenate([np.zeros(0, np.int64), *self.rows]),
            np.concatenate([np.zeros(0, np.int64), *self.cols]),
            n_classes,
            np.concatenate([np.zeros(0), *self.mass]),
        )
        n_old = len(f.leaf_count)
        sizes = np.bincount(lr - n_old, minlength=self.n_leaves - n_old)
        moved = np.asarray(self.moved, np.int32).reshape(-1, 2)
        arrays = {
            **nodes,
            "roots": f.roots,
            "leaf_ptr": appended(f.leaf_ptr, f.leaf_ptr[-1] + np.cumsum(sizes)),
            "leaf_class": appended(f.leaf_class, lc),
            "leaf_value": appended(f.leaf_value, lv),
            _COUNTS: appended(f.leaf_count, *self.counts),
            _FROM: appended(f.redirect_from, moved[:, 0]),
            _TO: appended(f.redirect_to, moved[:, 1]),
        }
        records = f._records.grown(n_old_nodes, nodes, moved)
        return FlatForest(arrays, n_classes, f.n_features, check=False, records=records)


class _WalkRecords:
    """The walk's node records (``_packed``) of a forest and of the forests promotions grew
    from it, in one buffer with spare rows. A promotion writes its new nodes' records into
    the spare rows and points each leaf it replaced at the replacement, in place (the
    records are the forests' own, derived from their arrays and never stored). A forest
    walks the first rows, as many as it has nodes, and follows a replaced leaf only to a
    node among them, so it sees no later promotion's redirects: the forest before a
    promotion answers as it did while and after the promotion is built."""

    def __init__(self, nodes: dict[str, np.ndarray], first: np.ndarray | None = None) -> None:
        """The records of node arrays ``nodes``, after the records ``first`` if given."""
        n_first = 0 if first is None else len(first)
        n = n_first + len(nodes["feature"])
        self._buffer = np.empty((n + n // 4 + 1, 4), np.int32)
        if first is not None:
            self._buffer[:n_first] = first
        _packed(nodes, slice(None), out=self._buffer[n_first:n])
        self._filled = n
        self._lock = threading.Lock()

    def first(self, n: int) -> np.ndarray:
        """The records of a forest of ``n`` nodes, read-only."""
        view = self._buffer[:n]
        view.flags.writeable = False
        return view

    def redirect(self, leaf_nodes: np.ndarray, to: np.ndarray) -> None:
        self._buffer[leaf_nodes, 3] = to  # 4-byte stores: a walk reads the old or the new

    def grown(self, n_old: int, nodes: dict[str, np.ndarray], moved: np.ndarray):
        """The records of the first ``n_old`` nodes, then those of ``nodes[...][n_old:]``,
        with leaf node ``moved[:, 0]`` redirected to node ``moved[:, 1]``: these records
        when no forest has grown from those first nodes yet and the spare rows suffice,
        else a copy."""
        new = {k: v[n_old:] for k, v in nodes.items()}
        n = n_old + len(new["feature"])
        with self._lock:
            in_place = self._filled == n_old and n <= len(self._buffer)
            if in_place:
                self._filled = n  # a second promotion of the same forest copies
        if in_place:
            out = self
            _packed(new, slice(None), out=self._buffer[n_old:n])
        else:
            out = _WalkRecords(new, first=self._buffer[:n_old])
            # drop redirects to nodes past n_old: a sibling promotion's, which these are not
            right = out._buffer[:n_old, 3]
            right[right >= n_old] = -1
        out.redirect(moved[:, 0], moved[:, 1])
        return out


def _packed(nodes: dict[str, np.ndarray], at: Any, out: np.ndarray | None = None) -> np.ndarray:
    """The walk's node records of ``nodes[...][at]``: one 16-byte record per node, so a step
    touches one cache line (split feature, float32 threshold bits, left and right child; a
    leaf, feature -1, keeps its leaf index where the left child would be, and where the
    right child would be -1 or, once a promotion replaced it, its replacement: the caller
    sets that from ``redirect_from`` / ``redirect_to``). For a float32 x,
    x <= t (float64) exactly when x <= the largest float32 <= t, so the walk compares in
    float32 (half the memory traffic) with the same outcome."""
    feature, threshold = nodes["feature"][at], nodes["threshold"][at]
    t32 = threshold.astype(np.float32)
    above = t32.astype(np.float64) > threshold
    t32[above] = np.nextafter(t32[above], np.float32(-np.inf))
    leaf = feature < 0
    out = np.empty((len(feature), 4), np.int32) if out is None else out
    out[:, 0] = feature
    out[:, 1] = t32.view(np.int32)
    out[:, 2] = np.where(leaf, nodes["leaf_of_node"][at], nodes["left"][at])
    out[:, 3] = nodes["right"][at]
    return out


def _members(nodes: np.ndarray) -> dict[int, np.ndarray]:
    """Node -> the row indices of ``nodes`` that hold it."""
    order = np.argsort(nodes, kind="stable")
    found, starts = np.unique(nodes[order], return_index=True)
    return {int(n): part for n, part in zip(found, np.split(order, starts[1:]), strict=True)}


def grow_leaf(x: np.ndarray, y: np.ndarray, max_features: Any, seed: int):
    """scikit-learn's ``ExtraTreeClassifier(max_features, random_state=seed).fit(x, y)`` on a
    leaf's few samples (float32 ``x``, finite), the same tree, without the checks of its
    arguments: a promotion grows ~4,500 such leaves (100 trees, the whole model and each
    procedure's), and the checks were three quarters of each fit's ~2 ms."""
    import sklearn
    from sklearn.tree import ExtraTreeClassifier

    tree = ExtraTreeClassifier(max_features=max_features, random_state=seed)
    with sklearn.config_context(skip_parameter_validation=True):
        return tree.fit(np.ascontiguousarray(x, np.float32), y, check_input=False)


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
def _descend(x, rows, nodes, thresholds, at, n):
    """Chains k < n, each sample ``x[rows[k]]`` from node ``at[k]``, down to their leaf
    nodes (into ``at``), a step of every chain at a time: independent load chains."""
    descending = True
    while descending:
        descending = False
        for k in range(n):
            node = at[k]
            f = nodes[node, 0]
            if f >= 0:
                at[k] = nodes[node, 2 + (x[rows[k], f] > thresholds[node, 1])]
                descending = True
            elif 0 <= nodes[node, 3] < nodes.shape[0]:
                # a leaf a promotion of this forest replaced: on from its replacement (a
                # later promotion's, past this forest's nodes, is not this forest's)
                at[k] = nodes[node, 3]
                descending = True


@njit(cache=True, nogil=True)
def _reached(i, t, node, nodes, leaf_ptr, leaf_class, leaf_value, leaves, proba):
    """Sample i reached leaf ``node`` in tree t: into ``leaves`` and/or ``proba``."""
    if leaves.shape[0] > 0:
        leaves[i, t] = node
    if proba.shape[0] > 0:
        leaf = nodes[node, 2]
        for j in range(leaf_ptr[leaf], leaf_ptr[leaf + 1]):
            proba[i, leaf_class[j]] += leaf_value[j]


@njit(cache=True, nogil=True)
def walk_trees(x, i, nodes, thresholds, roots, leaf_ptr, leaf_class, leaf_value, leaves, proba):
    """``_walk`` of sample i alone: _BLOCK trees taken down together (a single sample has
    one path per tree, so a block of samples gives it no independent chains), their leaves
    then added in tree order, so the sums have the same bits as ``_walk``'s."""
    at = np.empty(_BLOCK, np.int32)
    rows = np.full(_BLOCK, i, np.int64)
    for lo in range(0, roots.shape[0], _BLOCK):
        hi = min(lo + _BLOCK, roots.shape[0])
        at[: hi - lo] = roots[lo:hi]
        _descend(x, rows, nodes, thresholds, at, hi - lo)
        for k in range(hi - lo):
            _reached(i, lo + k, at[k], nodes, leaf_ptr, leaf_class, leaf_value, leaves, proba)


@njit(cache=True, nogil=True)
def _walk(x, nodes, thresholds, roots, leaf_ptr, leaf_class, leaf_value, leaves, proba):
    """Every sample through every tree: the leaf node reached into ``leaves`` (N, T) and/or
    the leaf distributions summed into ``proba`` (N, K); an empty array skips that output.
    Sums go tree by tree in tree order (the same bits on every call and after a bundle
    round-trip). _BLOCK samples go down a tree together; fewer take trees in blocks."""
    if x.shape[0] < _BLOCK:
        for i in range(x.shape[0]):
            walk_trees(
                x, i, nodes, thresholds, roots, leaf_ptr, leaf_class, leaf_value, leaves, proba
            )
        return
    at = np.empty(_BLOCK, np.int32)
    rows = np.empty(_BLOCK, np.int64)
    for lo in range(0, x.shape[0], _BLOCK):
        hi = min(lo + _BLOCK, x.shape[0])
        for t in range(roots.shape[0]):
            for k in range(hi - lo):
                at[k], rows[k] = roots[t], lo + k
            _descend(x, rows, nodes, thresholds, at, hi - lo)
            for k in range(hi - lo):
                _reached(lo + k, t, at[k], nodes, leaf_ptr, leaf_class, leaf_value, leaves, proba)
