"""Known classes and novelty for the ``best`` method: an extra-trees forest, and a novelty
score that adds nearest-neighbour distances to the forest's confidence.

Cues of a sample (all "higher = more novel"), ``CUES`` in this order:

- ``1 - max p``: one minus the forest's largest class probability (the extra-trees
  baseline's whole score);
- the entropy of the forest's class distribution, and minus the gap between its
  two largest probabilities;
- ``log knn3``, ``log knn1``, ``log top``: the log mean squared distance to the 3
  nearest training samples, to the nearest one, and to the nearest training
  sample of the forest's top class, in a feature-weighted space (each
  robust-scaled feature divided by its pooled within-class spread and multiplied
  by its Fisher ratio to the power 1/4), each relative to the same distance
  measured inside the training set between different trials (``_offsets``).
  They see how far a sample lies from the known objects' trials rather than
  which object the forest would vote for.

The novelty score is a fixed weighted sum of the cues (by default
``1 - max p + 0.1 log knn1 + 0.1 log top``). Fixed weights, not learned ones: a
logistic combination learned on pseudo-novel objects separated known from novel
samples as well (AUROC) but its scale moved between the Sect. VI-B probe and the
deployed model, so the tuned threshold did not carry over (see bench/research/explore_best.py
and docs/RESULTS.md).
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable

import numpy as np
from numba import njit

from app.data.dataset import TactileDataset
from app.framework.growing import ByBuffer, appended, with_room
from app.framework.scaling import RobustInputScaler, flatten
from app.methods.forest import FlatForest
from app.methods.neighbours import ApproximateNeighbours

CUES = ("one_minus_maxp", "entropy", "neg_gap", "log_knn3", "log_knn1", "log_top")
#: the reference samples whose mean squared distance is the ``log_knn3`` cue
KNN = 3
#: added to every squared distance before its log (public, as ``KNN`` and
#: ``nearest_from_products``: ``best``'s small-batch scorer computes the same cues)
DISTANCE_EPS = 1e-6
_ROWS = 8192  # rows a blocked pass over the samples takes at a time
_PROJECTED_ROWS = 4096  # reference rows projected together (``ReferenceDistances``)
_NO_GROUPS = np.zeros(0, np.int64)  # ``nearest_from_products`` leaving no reference out
#: reference rows projected in this process, by the buffer they begin: (rows, centre, basis,
#: coordinates, residual norms, squared norms), for ``ReferenceDistances._projection``
_PROJECTIONS = ByBuffer()


def fisher_weights(z: np.ndarray, y: np.ndarray, n_classes: int) -> np.ndarray:
    """Per-feature weights fisher^(1/4) / within-class spread (see the module docstring).

    One pass over the samples for the class means and one for the spreads, whatever the
    number of classes (a mask per class would cost N x K)."""
    means = class_means(z, y, n_classes)
    dof = max(len(z) - n_classes, 1)
    sq = np.zeros(z.shape[1])
    for lo in range(0, len(z), _ROWS):
        rows = slice(lo, lo + _ROWS)
        sq += ((z[rows] - means[y[rows]]) ** 2).sum(axis=0)
    within = np.sqrt(sq / dof) + 1e-3
    fisher = (means.std(axis=0) / within) ** 2
    return (fisher**0.25 / within).astype(np.float32)


def class_means(z: np.ndarray, y: np.ndarray, n_classes: int) -> np.ndarray:
    """(K, D) float64 mean of each class's rows of ``z`` (one sparse product)."""
    from scipy.sparse import csr_matrix

    y = np.asarray(y, np.int64)
    counts = np.bincount(y, minlength=n_classes).astype(np.float64)
    onehot = csr_matrix((1.0 / counts[y], (y, np.arange(len(y)))), shape=(n_classes, len(y)))
    return np.asarray(onehot @ np.asarray(z, np.float64))


class _Unweighted:
    """Rows of the weighted reference samples ``reference / weights``, divided on demand: a
    promotion reads a few of them, and the whole quotient is the size of the reference."""

    def __init__(self, reference: np.ndarray, weights: np.ndarray) -> None:
        self.reference, self.weights = reference, weights

    def __len__(self) -> int:
        return len(self.reference)

    def __getitem__(self, rows: np.ndarray) -> np.ndarray:
        return self.reference[rows] / self.weights


class ForestCues:
    """Scaler + forest + weighted reference samples: the known-class model and raw cues."""

    def __init__(
        self,
        scaler: RobustInputScaler,
        forest: FlatForest,
        weights: np.ndarray,
        distances: ReferenceDistances,
        reference_labels: np.ndarray,
        offsets: np.ndarray,
    ) -> None:
        self.scaler = scaler
        self.forest = forest
        self.weights = np.asarray(weights, np.float32)
        self.distances = distances
        self.reference = distances.reference
        self.reference_labels = np.asarray(reference_labels, np.int64)
        if self.reference_labels.shape != (len(self.reference),):
            raise ValueError("novelty reference samples and labels differ in number")
        if len(self.reference_labels) and (
            self.reference_labels.min() < 0 or self.reference_labels.max() >= forest.n_classes
        ):
            raise ValueError("novelty reference labels are out of range")
        # log-distance offsets: knn3, knn1 (global), then each class's own trial spacing
        self.offsets = np.asarray(offsets, np.float64)
        if self.offsets.shape != (2 + forest.n_classes,):
            raise ValueError("novelty distance offsets do not match the classes")

    @classmethod
    def fit(
        cls,
        x: np.ndarray,
        y: np.ndarray,
        trials: np.ndarray,
        n_classes: int,
        n_estimators: int,
        max_features,
        seed: int,
        n_jobs: int | None,
        components: int = 0,
        grower: str = "gini",
        codes: int = 0,
        approximate_above: int = 0,
    ) -> ForestCues:
        """``grower``, ``codes``: ``FlatForest.grow``'s; ``approximate_above``:
        ``ReferenceDistances.fit``'s."""
        scaler = RobustInputScaler().fit(x)
        z = scaler.transform(x)
        forest = FlatForest.grow(
            z, y, n_classes, n_estimators, max_features, seed, n_jobs, grower, codes
        )
        w = fisher_weights(z, y, n_classes)
        distances = ReferenceDistances.fit(z * w, components, approximate_above)
        return cls(
            scaler,
            forest,
            w,
            distances,
            y,
            _offsets(distances, np.asarray(y), np.asarray(trials), n_classes),
        )

    def with_samples(
        self, x: np.ndarray, y: np.ndarray, n_classes: int, max_features, seed: int
    ) -> ForestCues:
        """These cues with samples ``x`` (N, D) of classes ``y`` learnt without a refit
        (``FlatForest.with_samples``): the scaler, the feature weights, the distance basis and
        the global offsets stay as fitted; the samples join the reference (and its index), and
        a new class's trial spacing is measured among its own samples, each taken as a trial
        of its own (the median of the known classes' spacings for a class of one sample)."""
        z = self.scaled(x)
        zw = z * self.weights
        y = np.asarray(y, np.int64)
        distances = self.distances.with_points(zw)
        spacing = []
        fallback = float(np.median(self.offsets[2:]))
        for c in range(self.forest.n_classes, n_classes):
            pts = distances.coordinates(zw[y == c]).astype(np.float64)
            if len(pts) < 2:
                spacing.append(fallback)
                continue
            d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2)
            np.fill_diagonal(d2, np.inf)
            spacing.append(float(np.median(np.log(d2.min(axis=1) + DISTANCE_EPS))))
        return ForestCues(
            self.scaler,
            self.forest.with_samples(
                z,
                y,
                n_classes,
                _Unweighted(self.reference, self.weights),  # the scaled samples it has learnt
                self.reference_labels,
                max_features,
                seed,
            ),
            self.weights,
            distances,
            np.concatenate([self.reference_labels, y]),
            np.r_[self.offsets, spacing],
        )

    def scaled(self, x: np.ndarray) -> np.ndarray:
        return self.scaler.transform(x)

    def proba(self, z: np.ndarray) -> np.ndarray:
        return self.forest.predict_proba(z)

    def cues(self, z: np.ndarray, proba: np.ndarray, entropy: bool = True) -> np.ndarray:
        """(N, len(CUES)) raw cues of scaled samples ``z`` with forest probabilities ``proba``;
        the entropy column is 0 without ``entropy`` (a log of all K classes per sample, for a
        cue that ``best`` weighs 0)."""
        # the two largest of each row: the largest, then the largest of the rest (two passes;
        # a sort or partition of K mostly-zero values costs many times that)
        rows, best = np.arange(len(proba)), proba.argmax(axis=1)
        first = proba[rows, best]
        if proba.shape[1] > 1:
            proba[rows, best] = -np.inf
            second = proba.max(axis=1)
            proba[rows, best] = first  # the caller's posteriors, as they were
        else:
            second = np.zeros(len(proba))
        entropy = (
            -(proba * np.log(np.clip(proba, 1e-12, None))).sum(axis=1)
            if entropy
            else np.zeros(len(proba))
        )
        gap = first - second
        near = self.distances.nearest(z * self.weights, self.reference_labels, best)
        log_d = np.log(near + DISTANCE_EPS)
        off = self.offsets
        return np.stack(
            [
                1.0 - first,
                entropy,
                -gap,
                log_d[:, 0] - off[0],
                log_d[:, 1] - off[1],
                log_d[:, 2] - off[2 + best],
            ],
            axis=1,
        )

    def get_state(self) -> dict[str, np.ndarray]:
        out = {f"forest/{k}": v for k, v in self.forest.get_state().items()}
        out.update({f"scaler/{k}": v for k, v in self.scaler.get_state().items()})
        out["weights"], out["reference"] = self.weights, self.reference
        out["center"] = self.distances.center  # a grown reference's mean is not its centre
        if self.distances.basis is not None:
            out["basis"] = self.distances.basis
        if self.distances.index is not None:
            out["index"] = self.distances.index.to_bytes()
        out["reference_labels"], out["offsets"] = self.reference_labels, self.offsets
        return out

    @classmethod
    def from_state(
        cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int
    ) -> ForestCues:
        """The cues ``get_state`` stored. Built from a store's read-only parts, the cues of
        those very arrays are built once while they live: a process that loads version
        after version (an API process, after each enrolment) shares them between versions,
        as enrolment does (``KnownModel.__deepcopy__``), instead of projecting every
        reference sample and reading the neighbour index again (seconds at 10,000
        objects)."""
        key = _built_key(arrays, n_classes, n_features)
        if key is not None and (built := _built(key, arrays)) is not None:
            return built
        out = cls._from_state(arrays, n_classes, n_features)
        if key is not None:
            _remember(key, arrays, out)
        return out

    @classmethod
    def _from_state(
        cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int
    ) -> ForestCues:
        def part(prefix: str) -> dict[str, np.ndarray]:
            return {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)}

        scaler = RobustInputScaler()
        scaler.set_state(part("scaler/"))
        forest = FlatForest.from_state(part("forest/"), n_classes, n_features)
        weights, reference = arrays["weights"], arrays["reference"]
        if (
            weights.shape != (n_features,)
            or reference.ndim != 2
            or reference.shape[1] != n_features
        ):
            raise ValueError("novelty reference samples do not match the inputs")
        basis = arrays.get("basis")  # absent: exact distances (and bundles made before it)
        if basis is not None and (basis.ndim != 2 or basis.shape[0] != n_features):
            raise ValueError("novelty distance basis does not match the inputs")
        return cls(
            scaler,
            forest,
            weights,
            ReferenceDistances(
                reference,
                basis,
                None if "index" not in arrays else arrays["index"],
                center=arrays.get("center"),  # absent in bundles made before growth: the mean
            ),
            arrays["reference_labels"],
            arrays["offsets"],
        )


# ForestCues built from read-only arrays: key -> (the cues, those arrays), weakly held, so
# an entry lives exactly as long as what it names
_BUILT: dict[tuple, tuple[weakref.ref, dict[str, weakref.ref]]] = {}
_BY_VALUE_BYTES = 1 << 16  # smaller arrays (a bundle's head holds them) are named by value


def _built_key(arrays: dict[str, np.ndarray], n_classes: int, n_features: int) -> tuple | None:
    """What names cues built from ``arrays``: the identities of the large ones, where
    nothing can write into any of them, and the bytes of the small ones (None otherwise:
    such cues are built each time)."""
    from app.framework.bundle import unchangeable

    key: list = [n_classes, n_features]
    for name in sorted(arrays):
        a = arrays[name]
        if not isinstance(a, np.ndarray):
            return None
        if unchangeable(a):
            key.append((name, id(a)))
        elif a.nbytes < _BY_VALUE_BYTES:
            key.append((name, a.dtype.str, a.shape, a.tobytes()))
        else:
            return None
    return tuple(key)


def _built(key: tuple, arrays: dict[str, np.ndarray]) -> ForestCues | None:
    entry = _BUILT.get(key)
    if entry is None:
        return None
    cues, refs = entry[0](), entry[1]
    if cues is None or any(ref() is not arrays[name] for name, ref in refs.items()):
        return None  # gone, or another array took a dead one's id
    return cues


def _remember(key: tuple, arrays: dict[str, np.ndarray], cues: ForestCues) -> None:
    from app.framework.bundle import unchangeable

    for old in [k for k, (c, _) in _BUILT.items() if c() is None]:
        del _BUILT[old]
    held = {name: weakref.ref(a) for name, a in arrays.items() if unchangeable(a)}
    _BUILT[key] = (weakref.ref(cues), held)


class ReferenceDistances:
    """Squared distances from queries to the reference samples, in float32 about the
    reference mean (centring keeps |q|^2 small next to the distances, so float32's rounding
    stays far below a trial's spacing).

    With a ``basis`` (D, k) of the reference's top-k principal directions, a query q and a
    reference r split into their parts in that subspace and their residuals, and

        d^2(q, r) = |P q - P r|^2 + (|q_res| - |r_res|)^2,

    the exact distance except that the residuals are taken as parallel (a lower bound; exact
    when either residual is zero, so a sample's distance to itself is 0). It keeps what lies
    outside the known objects' subspace (a novel object's signature) and costs a k-dim
    product instead of a D-dim one: on the 960-feature simulator 64 components make the
    products ~2.5x cheaper. Without a basis the distance is exact.

    That distance is the Euclidean one between the points ``(P q, |q_res|)``
    (``coordinates``), so an ``index`` (``ApproximateNeighbours``, or its bytes) over the
    reference's points finds the nearest ones without comparing a query with all of them;
    the nearest sample of one class is still found exactly, among that class's samples.
    """

    def __init__(
        self,
        reference: np.ndarray,
        basis: np.ndarray | None = None,
        index: ApproximateNeighbours | np.ndarray | None = None,
        center: np.ndarray | None = None,
    ) -> None:
        self.reference = np.asarray(reference, np.float32)
        self.basis = None if basis is None else np.ascontiguousarray(basis, np.float32)
        if self.reference.ndim != 2 or (
            self.basis is not None and self.basis.shape[0] != self.reference.shape[1]
        ):
            raise ValueError("novelty reference samples and distance basis do not match")
        # the reference mean; given when samples join a fitted reference, whose residual norms
        # (and index) depend on it
        self.center = (
            self.reference.mean(axis=0, dtype=np.float64).astype(np.float32)
            if center is None
            else np.asarray(center, np.float32)
        )
        if self.center.shape != (self.reference.shape[1],):
            raise ValueError("novelty reference centre does not match the inputs")
        self._ref, self._ref_res, self._ref_sq = self._projection()
        self.index: ApproximateNeighbours | None = None
        self._points: np.ndarray | None = None  # the reference's coordinates, with an index
        if index is not None:
            self._index(index)
        self._groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def fit(
        cls, reference: np.ndarray, components: int, approximate_above: int = 0
    ) -> ReferenceDistances:
        """``components`` principal directions of the reference (0, or at least its rank:
        exact); an approximate index when it holds more than ``approximate_above`` samples
        (0: never)."""
        reference = with_room(np.asarray(reference, np.float32))  # a promotion appends to it
        basis = None
        if 0 < components < min(reference.shape):
            basis = _principal_directions(reference, components)
        out = cls(reference, basis)
        if 0 < approximate_above < len(reference):
            out._index(ApproximateNeighbours.build)
        return out

    def with_points(self, q: np.ndarray) -> ReferenceDistances:
        """These distances with the reference samples ``q`` (N, D) added: same basis and
        centre, and the index (if any) with their points added (``with_points``). The
        reference and what is derived from it grow by appending (``growing.appended``):
        only the new samples are projected, to the bits a load of the result computes."""
        n_old = len(self.reference)
        out = copy.copy(self)
        out.reference = appended(self.reference, np.asarray(q, np.float32))
        ref, res, sq = out._projected(n_old)
        out._ref, out._ref_sq = appended(self._ref, ref), appended(self._ref_sq, sq)
        out._ref_res = None if res is None else appended(self._ref_res, res)
        out._groups = None
        if self.index is not None:  # over the new reference's points, as a load computes them
            out._index(self.index.with_points, appended(self._points, _points(ref, res)))
        return out

    def _projection(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """``_projected(0)``, taking the rows this process projected before, with the same
        centre and basis, for a reference this one begins with (``_PROJECTIONS``): a
        promoted version that another process built is loaded as the version before with
        rows appended, and projecting every row again took 1.4 s at 10,000 objects."""
        n = len(self.reference)
        held = _PROJECTIONS.get(self.reference)
        if held is not None and held[0] <= n and self._same_space(held[1], held[2]):
            rows, ref, res, sq = held[0], *held[3:]
            new_ref, new_res, new_sq = self._projected(rows)
            out = (
                appended(ref, new_ref),
                None if res is None else appended(res, new_res),
                appended(sq, new_sq),
            )
        else:
            out = self._projected(0)
        _PROJECTIONS.put(self.reference, (n, self.center, self.basis, *out))
        return out

    def _same_space(self, center: np.ndarray, basis: np.ndarray | None) -> bool:
        if (basis is None) != (self.basis is None):
            return False
        return np.array_equal(center, self.center) and (
            basis is None or basis is self.basis or np.array_equal(basis, self.basis)
        )

    def _projected(self, start: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(``_split``'s coordinates and residual norms, squared norms of the coordinates) of
        the reference from row ``start`` on. Computed in blocks of ``_PROJECTED_ROWS`` rows
        from row 0, each padded to that many: a row's bits then do not depend on how many
        rows were projected with it (a matrix product's kernel can depend on its shape), so
        rows projected when a promotion appended them match those a load projects."""
        n, size = len(self.reference), _PROJECTED_ROWS
        width = self.reference.shape[1] if self.basis is None else self.basis.shape[1]
        ps, ress = [np.zeros((0, width), np.float32)], [np.zeros(0, np.float32)]
        for lo in range(start - start % size, n, size):
            rows = self.reference[lo : lo + size]
            if len(rows) < size:
                rows = np.r_[rows, np.zeros((size - len(rows), rows.shape[1]), np.float32)]
            p, res = self._split(rows)
            keep = slice(max(start - lo, 0), min(n - lo, size))
            ps.append(p[keep])
            ress.append(res[keep] if res is not None else ress[0])
        p = with_room(*ps)  # a promotion appends to them (``with_points``)
        res = None if self.basis is None else with_room(*ress)
        return p, res, with_room((p**2).sum(axis=1))

    def _index(
        self,
        index: ApproximateNeighbours | np.ndarray | Callable,
        points: np.ndarray | None = None,
    ) -> None:
        """Search through ``index``: an index, its bytes, or a function that builds one from
        the reference's coordinates (``points``, where the caller has them)."""
        if points is None:
            points = _points(self._ref, self._ref_res)
        if isinstance(index, np.ndarray):
            index = ApproximateNeighbours.from_bytes(index, points)
        elif callable(index) and not isinstance(index, ApproximateNeighbours):
            index = index(points)
        self.index, self._points = index, points

    def coordinates(self, q: np.ndarray) -> np.ndarray:
        """(N, k + 1) points whose Euclidean distances are this class's distances ((N, D)
        centred queries when exact)."""
        p, res = self._split(q)
        return p if res is None else np.concatenate([p, res[:, None]], axis=1)

    def _class_groups(self, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference's points sorted by label, each label's first row and the order."""
        if self._groups is None:
            order = np.argsort(labels, kind="stable")
            starts = np.searchsorted(labels[order], np.arange(int(labels.max()) + 2))
            self._groups = (np.ascontiguousarray(self._points[order]), starts, order)
        return self._groups

    def _split(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(subspace coordinates, residual norms) of centred queries; no residual when exact."""
        qc = np.asarray(q, np.float32) - self.center
        if self.basis is None:
            return qc, None
        p = qc @ self.basis
        res = (qc**2).sum(axis=1) - (p**2).sum(axis=1)
        return p, np.sqrt(np.maximum(res, 0.0))

    def nearest(self, q: np.ndarray, labels: np.ndarray, top: np.ndarray) -> np.ndarray:
        """(N, 3) float64 per query: the mean squared distance to its 3 nearest references, to
        the nearest one, and to the nearest one labelled ``top[i]`` (inf if none is)."""
        if self.index is not None:
            return self.nearest_to_points(self.coordinates(q), labels, top)
        p, res = self._split(q)
        g = p @ self._ref.T
        no_res = np.zeros(0, np.float32)
        return nearest_from_products(
            g,
            (p**2).sum(axis=1),
            self._ref_sq,
            no_res if res is None else res,
            no_res if self._ref_res is None else self._ref_res,
            np.asarray(labels, np.int64),
            np.asarray(top, np.int64),
            KNN,
            _NO_GROUPS,
            _NO_GROUPS,
        )

    def nearest_to_points(
        self, points: np.ndarray, labels: np.ndarray, top: np.ndarray
    ) -> np.ndarray:
        """``nearest`` through the index, from the queries' ``coordinates`` (a caller that
        computes them itself: ``small_batch``)."""
        d2, _ = self.index.search(points, min(KNN, len(self.reference)))
        grouped, starts, _ = self._class_groups(np.asarray(labels, np.int64))
        own = _nearest_in_class(points, grouped, starts, np.asarray(top, np.int64))
        return np.stack([d2.mean(axis=1), d2[:, 0], own], axis=1)

    def nearest_in_other_trials(
        self, rows: slice, labels: np.ndarray, trials: np.ndarray
    ) -> np.ndarray:
        """``nearest``'s three columns for the reference's own samples ``rows`` (exact search),
        each compared only with the samples of other ``trials`` and its own label as
        ``top``: one matrix product and one compiled pass, where masking a distance matrix
        took seven passes over it (``_offsets``)."""
        labels, trials = np.asarray(labels, np.int64), np.asarray(trials, np.int64)
        res = np.zeros(0, np.float32) if self._ref_res is None else self._ref_res
        return nearest_from_products(
            self._ref[rows] @ self._ref.T,
            self._ref_sq[rows],
            self._ref_sq,
            res[rows] if len(res) else res,
            res,
            labels,
            labels[rows],
            KNN,
            trials[rows],
            trials,
        )

    def reference_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What ``nearest`` takes from the reference, for a caller that computes the queries'
        products itself (exact search only: no ``index``): the (k, N) transposed view it
        multiplies the queries' coordinates by, their squared norms, and the residual norms
        (empty when exact). The arrays are this object's own: read, never written."""
        res = np.zeros(0, np.float32) if self._ref_res is None else self._ref_res
        return self._ref.T, self._ref_sq, res

    def to_reference(self, q: np.ndarray) -> np.ndarray:
        """(N, n_reference) squared distances, floored at 0."""
        p, res = self._split(q)
        d2 = p @ self._ref.T
        d2 *= -2.0
        d2 += (p**2).sum(axis=1)[:, None]
        d2 += self._ref_sq[None, :]
        if res is not None:
            d2 += (res[:, None] - self._ref_res[None, :]) ** 2
        return np.maximum(d2, 0.0, out=d2)


def _points(ref: np.ndarray, res: np.ndarray | None) -> np.ndarray:
    """The points whose Euclidean distances are ``ReferenceDistances``' distances, with
    room behind them (``with_points`` appends to them)."""
    return with_room(ref if res is None else np.c_[ref, res])


@njit(cache=True, nogil=True)
def nearest_from_products(g, q_sq, ref_sq, q_res, ref_res, labels, top, k, q_groups, ref_groups):
    # One pass over the query-reference products instead of a full distance matrix and its
    # partition and masked minimum (each a pass of its own): the formula of to_reference.
    # With groups (not empty), a reference in the query's group is left out.
    n, m = g.shape
    k = min(k, m)
    grouped = q_groups.shape[0] > 0
    out = np.empty((n, 3))
    smallest = np.empty(k)  # ascending
    for i in range(n):
        smallest[:] = np.inf
        own = np.inf
        for j in range(m):
            if grouped and ref_groups[j] == q_groups[i]:
                continue
            d = q_sq[i] - 2.0 * g[i, j] + ref_sq[j]
            if q_res.shape[0] > 0:
                r = q_res[i] - ref_res[j]
                d += r * r
            d = max(d, 0.0)
            if d < smallest[k - 1]:
                pos = k - 1
                while pos > 0 and smallest[pos - 1] > d:
                    smallest[pos] = smallest[pos - 1]
                    pos -= 1
                smallest[pos] = d
            if labels[j] == top[i] and d < own:
                own = d
        out[i, 0] = smallest.sum() / k
        out[i, 1] = smallest[0]
        out[i, 2] = own
    return out


@njit(cache=True, nogil=True)
def _squared(a, i, b, j):
    # squared Euclidean distance between row i of a and row j of b
    d = 0.0
    for f in range(a.shape[1]):
        r = a[i, f] - b[j, f]
        d += r * r
    return d


@njit(cache=True, nogil=True)
def _nearest_in_class(points, grouped, starts, top):
    # squared distance from each point to the nearest reference point of class top[i]
    out = np.full(points.shape[0], np.inf)
    for i in range(points.shape[0]):
        for j in range(starts[top[i]], starts[top[i] + 1]):
            out[i] = min(out[i], _squared(points, i, grouped, j))
    return out


@njit(cache=True, nogil=True)
def _spacing_in_class(grouped, trials, starts):
    # per sorted row, the squared distance to the nearest row of its class in another trial
    out = np.full(grouped.shape[0], np.inf)
    for c in range(starts.shape[0] - 1):
        for i in range(starts[c], starts[c + 1]):
            for j in range(starts[c], starts[c + 1]):
                if trials[i] != trials[j]:
                    out[i] = min(out[i], _squared(grouped, i, grouped, j))
    return out


def _principal_directions(rows: np.ndarray, components: int) -> np.ndarray:
    """(D, k) top principal directions of ``rows``: from the D x D scatter matrix,
    accumulated in row blocks, when there are many more rows than columns (an SVD of the
    centred rows would hold N x D float64 twice), else from that SVD."""
    n, d = rows.shape
    mean = rows.mean(axis=0, dtype=np.float64)
    if n <= 4 * d:
        return np.linalg.svd(rows - mean, full_matrices=False)[2][:components].T
    scatter = np.zeros((d, d))
    for lo in range(0, n, _ROWS):
        block = rows[lo : lo + _ROWS] - mean
        scatter += block.T @ block
    _, vectors = np.linalg.eigh(scatter)
    return vectors[:, ::-1][:, :components]


def _offsets(
    distances: ReferenceDistances,
    y: np.ndarray,
    trials: np.ndarray,
    n_classes: int,
    block: int = 1024,
) -> np.ndarray:
    """Typical log distances *within* the reference set, each sample compared with the samples
    of other trials only: median log knn3 and knn1 over all samples, and per class the median
    log distance to the nearest other trial of the same class (the class's trial spacing).

    Subtracting them makes the distance cues relative to the reference's own density, which
    differs between the Sect. VI-B probe (one trial per class held out, fewer classes) and the
    deployed model (more trials and classes, so nearer neighbours for every query).
    """
    if distances.index is not None:
        knn3, knn1, own = _approximate_spacing(distances, y, trials)
        return _median_offsets(knn3, knn1, own, y, n_classes)
    n = len(distances.reference)
    found = np.empty((n, 3))
    for lo in range(0, n, block):  # row blocks keep memory at block x n
        rows = slice(lo, min(lo + block, n))
        found[rows] = distances.nearest_in_other_trials(rows, y, trials)
    return _median_offsets(found[:, 0], found[:, 1], found[:, 2], y, n_classes)


def _approximate_spacing(
    distances: ReferenceDistances, y: np.ndarray, trials: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_offsets``' per-sample distances through the index: its nearest samples in other
    trials (asking for as many more as a trial holds) and, exactly, within its class."""
    _, per_trial = np.unique(trials, return_counts=True)
    k = min(len(y), KNN + int(per_trial.max()))
    knn3, knn1 = np.empty(len(y)), np.empty(len(y))
    for lo in range(0, len(y), _ROWS):
        rows = slice(lo, lo + _ROWS)
        d2, ids = distances.index.search(distances._points[rows], k)
        d2[(ids < 0) | (trials[np.maximum(ids, 0)] == trials[rows, None])] = np.inf
        d2.sort(axis=1)
        knn3[rows], knn1[rows] = d2[:, :KNN].mean(axis=1), d2[:, 0]
    grouped, starts, order = distances._class_groups(np.asarray(y, np.int64))
    own = np.empty(len(y))
    own[order] = _spacing_in_class(grouped, np.asarray(trials, np.int64)[order], starts)
    return knn3, knn1, own


def _median_offsets(knn3, knn1, own, y, n_classes) -> np.ndarray:
    def median_log(values: np.ndarray, default: float) -> float:
        finite = values[np.isfinite(values)]
        return float(np.median(np.log(finite + DISTANCE_EPS))) if len(finite) else default

    overall = median_log(own, 0.0)
    order = np.argsort(y, kind="stable")
    by_class = np.split(own[order], np.searchsorted(y[order], np.arange(1, n_classes)))
    spacing = [median_log(values, overall) for values in by_class]
    return np.r_[median_log(knn3, 0.0), median_log(knn1, 0.0), spacing]


class KnownModel:
    """ForestCues and fixed cue weights: ``known_proba`` and the novelty score of the best
    method."""

    def __init__(self, cues: ForestCues, weights: np.ndarray) -> None:
        self.cues_model = cues
        self.weights = np.asarray(weights, np.float64)
        if self.weights.shape != (len(CUES),):
            raise ValueError(f"the novelty score needs {len(CUES)} cue weights")

    @classmethod
    def fit(
        cls,
        dataset: TactileDataset,
        weights: np.ndarray,
        n_estimators: int,
        max_features,
        seed: int,
        n_jobs: int | None,
        components: int = 0,
        grower: str = "gini",
        codes: int = 0,
        approximate_above: int = 0,
    ) -> KnownModel:
        cues = ForestCues.fit(
            flatten(dataset.samples),
            dataset.labels,
            dataset.trials,
            dataset.n_classes,
            n_estimators,
            max_features,
            seed,
            n_jobs,
            components,
            grower,
            codes,
            approximate_above,
        )
        return cls(cues, weights)

    def scores(self, x_flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(scaled inputs, known-class probabilities, novelty scores)."""
        z = self.cues_model.scaled(x_flat)
        p = self.cues_model.proba(z)
        entropy = bool(self.weights[CUES.index("entropy")] != 0)
        return z, p, self.cues_model.cues(z, p, entropy) @ self.weights

    def __deepcopy__(self, memo: dict) -> KnownModel:
        # Never changed after its fit (a refit makes a new one; the index and class groups
        # are caches that come out the same whoever builds them): the models that enrolment
        # derives share it, instead of copying the reference samples and the index (300 MB
        # at 10,000 objects) for every class or sample enrolled.
        return self

    def with_samples(
        self, x_flat: np.ndarray, y: np.ndarray, n_classes: int, max_features, seed: int
    ) -> KnownModel:
        """A new model with these samples learnt without a refit (``ForestCues.with_samples``)."""
        cues = self.cues_model.with_samples(x_flat, y, n_classes, max_features, seed)
        return KnownModel(cues, self.weights)

    def novelty(self, x_flat: np.ndarray, block: int = 1024) -> np.ndarray:
        """The novelty scores alone, ``block`` samples at a time: a block's posteriors are
        block x K (at 30,000 known objects all held-out samples at once would be tens of GB)."""
        out = np.empty(len(x_flat))
        for lo in range(0, len(x_flat), block):
            out[lo : lo + block] = self.scores(x_flat[lo : lo + block])[2]
        return out

    def get_state(self) -> dict[str, np.ndarray]:
        return self.cues_model.get_state()

    @classmethod
    def from_state(
        cls, arrays: dict[str, np.ndarray], weights: np.ndarray, n_classes: int, n_features: int
    ) -> KnownModel:
        return cls(ForestCues.from_state(arrays, n_classes, n_features), weights)


def relabelled(dataset: TactileDataset, idx: np.ndarray) -> TactileDataset:
    """The samples ``idx`` of ``dataset``, with only the classes present, relabelled 0 … K'-1."""
    sub = dataset.subset(idx)
    return sub.select_classes(np.unique(sub.labels))
