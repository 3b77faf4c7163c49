"""A fitted scikit-learn tree ensemble as plain int/float arrays, with its own inference.

Model bundles hold only JSON and numeric arrays (no pickle), so a fitted
``ExtraTreesClassifier`` is flattened into concatenated node arrays (split
feature, threshold, children) and its leaves' class distributions in compressed
sparse rows. Inference walks every tree at once in numpy, so predictions do not
depend on scikit-learn's private estimator layout and are bit-identical after a
bundle round-trip. Internal nodes' class counts are not kept (inference never
reads them), which keeps a 300-tree forest on PHAC-2 at a few MB instead of
hundreds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

_KEYS = ("feature", "threshold", "left", "right", "roots", "leaf_of_node", "leaf_ptr", "leaf_class",
         "leaf_value")


class FlatForest:
    """Class-probability trees (one output) flattened into arrays; see the module docstring."""

    def __init__(self, arrays: dict[str, np.ndarray], n_classes: int, n_features: int) -> None:
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
        self.n_classes = int(n_classes)
        self.n_features = int(n_features)
        self._children: np.ndarray | None = None  # (left, right) interleaved, built on first use
        self._threshold32: np.ndarray | None = None
        self._check()

    def _check(self) -> None:
        n = len(self.feature)
        if not (len(self.threshold) == len(self.left) == len(self.right) == len(self.leaf_of_node) == n):
            raise ValueError("forest node arrays differ in length")
        if len(self.roots) == 0 or self.roots.min() < 0 or self.roots.max() >= n:
            raise ValueError("forest roots are out of range")
        internal = self.feature >= 0
        if internal.any():
            kids = np.concatenate([self.left[internal], self.right[internal]])
            if kids.min() < 0 or kids.max() >= n or self.feature[internal].max() >= self.n_features:
                raise ValueError("forest children or split features are out of range")
        leaves = self.leaf_of_node[~internal]
        if leaves.min() < 0 or leaves.max() + 1 >= len(self.leaf_ptr):
            raise ValueError("forest leaves are out of range")
        if len(self.leaf_class) != len(self.leaf_value) or self.leaf_ptr[-1] != len(self.leaf_class):
            raise ValueError("forest leaf distributions are inconsistent")
        if len(self.leaf_class) and (self.leaf_class.min() < 0 or self.leaf_class.max() >= self.n_classes):
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
        feats, thrs, lefts, rights, roots, leaf_of = [], [], [], [], [], []
        ptr, leaf_cls, leaf_val = [0], [], []
        offset = n_leaves = 0
        for est in forest.estimators_:
            t = est.tree_
            n = t.node_count
            is_leaf = t.children_left < 0
            feats.append(np.where(is_leaf, -1, t.feature).astype(np.int32))
            thrs.append(t.threshold.astype(np.float64))
            lefts.append(np.where(is_leaf, -1, t.children_left + offset).astype(np.int32))
            rights.append(np.where(is_leaf, -1, t.children_right + offset).astype(np.int32))
            roots.append(offset)
            ids = np.full(n, -1, np.int32)
            ids[is_leaf] = n_leaves + np.arange(int(is_leaf.sum()), dtype=np.int32)
            leaf_of.append(ids)
            values = t.value[is_leaf, 0, :].astype(np.float64)
            values /= np.maximum(values.sum(axis=1, keepdims=True), 1e-300)
            rows, cols = np.nonzero(values)
            counts = np.bincount(rows, minlength=len(values))
            ptr.extend((ptr[-1] + np.cumsum(counts)).tolist())
            leaf_cls.append(cols.astype(np.int32))
            leaf_val.append(values[rows, cols])
            offset += n
            n_leaves += len(values)
        arrays = {
            "feature": np.concatenate(feats), "threshold": np.concatenate(thrs),
            "left": np.concatenate(lefts), "right": np.concatenate(rights),
            "roots": np.asarray(roots, np.int32), "leaf_of_node": np.concatenate(leaf_of),
            "leaf_ptr": np.asarray(ptr, np.int64), "leaf_class": np.concatenate(leaf_cls),
            "leaf_value": np.concatenate(leaf_val),
        }
        return cls(arrays, len(classes), int(forest.n_features_in_))

    # --------------------------------------------------------------- inference
    def apply(self, x: np.ndarray) -> np.ndarray:
        """(N, n_trees) global node index of the leaf each sample reaches in each tree."""
        x = np.asarray(x, np.float32)  # scikit-learn compares float32 inputs with float64 thresholds
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(f"expected inputs of shape (N, {self.n_features}), got {x.shape}")
        if self._children is None:
            self._prepare_walk()
        n, t = len(x), self.n_trees
        out = np.empty(n * t, np.int32)
        # One (sample, tree) walker per entry, all stepped together; a walker leaves the
        # active set at its leaf, so each step costs only the paths still descending.
        index = np.int32 if x.size < 2**31 and n * t < 2**31 else np.int64  # int32: less traffic
        walker = np.arange(n * t, dtype=index)
        offset = np.repeat(np.arange(n, dtype=index) * self.n_features, t)  # row start in x
        node = np.tile(self.roots, n)
        feature = self.feature[node]
        flat = x.ravel()
        while len(walker):
            descending = feature >= 0
            if not descending.all():
                out[walker[~descending]] = node[~descending]
                walker, node = walker[descending], node[descending]
                offset, feature = offset[descending], feature[descending]
            go_right = flat[offset + feature] > self._threshold32[node]
            node = self._children[2 * node + go_right]
            feature = self.feature[node]
        return out.reshape(n, t)

    def _prepare_walk(self) -> None:
        # For a float32 x, x <= t (float64) exactly when x <= the largest float32 <= t, so
        # the walk compares in float32 (half the memory traffic) with the same outcome.
        t32 = self.threshold.astype(np.float32)
        above = t32.astype(np.float64) > self.threshold
        t32[above] = np.nextafter(t32[above], np.float32(-np.inf))
        self._threshold32 = t32
        self._children = np.stack([self.left, self.right], axis=1).ravel()

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(N, K) mean over trees of the reached leaf's class distribution."""
        nodes = self.apply(x)
        n, t = nodes.shape
        leaf = self.leaf_of_node[nodes.ravel()]
        start = self.leaf_ptr[leaf]
        count = self.leaf_ptr[leaf + 1] - start
        total = int(count.sum())
        owner = np.repeat(np.repeat(np.arange(n), t), count)
        first = np.repeat(np.cumsum(count) - count, count)
        pos = np.repeat(start, count) + (np.arange(total) - first)
        flat = np.bincount(owner * self.n_classes + self.leaf_class[pos], weights=self.leaf_value[pos],
                           minlength=n * self.n_classes)
        return flat.reshape(n, self.n_classes) / t

    # ------------------------------------------------------------ persistence
    def get_state(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in _KEYS}

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int) -> FlatForest:
        return cls(arrays, n_classes, n_features)

    def __deepcopy__(self, memo: dict) -> FlatForest:
        # Immutable after construction: recognizers copied by enrolment share it.
        return self
