"""Naming a table of objects at once: several distinct objects, each touched one or more
times, named jointly so that no two of them get the same registered class.

A robot handed a table of new objects knows which touches belong to which physical object
(``objects``: the caller's label of every sample). Each object is answered from all its
touches (the means of ``fuse_groups``), and the objects are then named together: the
assignment of classes to objects that maximises the summed log-scores
(``assign_table``, the Hungarian algorithm), where every registered class, known or novel,
names at most one object and the repeatable column ``UNREGISTERED`` ("novel, not any
registered class") may name several. Named one at a time, two objects that feel alike both
take the likelier class; named together, the second gives way to its next best.

The scores of an object (``TableScorer``), with P(novel) the probability that it is none of
the known classes, from its mean novelty score:

- known class j: ``log(1 - P(novel)) + log p_known[j] - max_i log p_known[i]``;
- registered novel class l: ``log P(novel) + log(1 - unregistered_prior) + log p_novel[l]``,
  and ``UNREGISTERED``: ``log P(novel) + log unregistered_prior``, both less the larger of
  the two sides' best (``log P(novel)`` alone where no novel class is registered).

Each side's best class scores exactly its side's ``log P``: what an object is called alone,
known or novel, is then the route's answer (P(novel) above one half exactly where its score
is above the routing threshold, with ``novelty_offset`` 0), on any model and sensor, and the
classes' probabilities only say what giving way costs within a side. (Scored raw, a
forest's flat known probabilities, 0.1 each on the BioTac pilot, lost every known object of
a table to ``UNREGISTERED``, which carries no class probability.)

P(novel) is a logistic function of the novelty score: its slope is fitted on the held-out
scores the model tuned its threshold on (``NoveltyTuning``'s curves of held-out known and
validation-novel scores, balanced), its centre is the threshold ``recognize_batch`` would
route the object by (the model's own, or the one keeping ``known_kept``), so an object
alone at P(novel) = 1/2 sits exactly on the routing threshold. The routing thus takes part
in the assignment instead of being decided touch by touch. A model without those curves
routes hard (P(novel) is ``floor`` or ``1 - floor``).

Raw trials: for a model fitted on raw BioTac trials, ``name_table`` takes what
``recognize_trials`` takes (a list of trials, ``objects`` one label per trial); each trial's
finger images then count as touches of its object.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from app.framework.errors import TableError
from app.framework.fusion import group_mean

__all__ = [
    "UNREGISTERED",
    "TableAnswer",
    "TableScorer",
    "assign_table",
    "group_touches",
    "name_table",
    "object_groups",
]

#: the name of the repeatable column in ``name_table``'s column names: an object that is
#: novel and none of the registered classes (several objects may take it)
UNREGISTERED: None = None


@dataclass(frozen=True)
class TableAnswer:
    """The name of one distinct object of a table (``name_table``, first-appearance order)."""

    #: the caller's label of the object
    object: str | int
    #: indices of the samples (or raw trials) of this object in the input
    rows: np.ndarray
    #: the column of ``name_table``'s columns assigned to it
    column: int
    #: the column its own scores' argmax gives (what it would be named alone)
    alone: int
    #: >= 0: the summed log-score lost by the best assignment that gives this object another
    #: column (0 when tied; inf where no other assignment exists)
    margin: float


def assign_table(
    scores: np.ndarray, repeatable: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The assignment of columns to objects that maximises the summed ``scores``.

    ``scores``: (n_objects, n_columns) finite log-scores; ``repeatable``: (n_columns,) bool,
    the columns several objects may share (each replicated n_objects times for
    ``scipy.optimize.linear_sum_assignment``); every other column names one object at most.

    Returns ``(columns, alone, margins)``, each (n_objects,): the assigned column, the
    row's argmax (first of ties), and the summed score lost by the best assignment that
    gives the object any other column (0 when tied, inf where none exists). ValueError
    naming the problem for a wrong shape, a non-finite score, or more objects than the
    columns can take.
    """
    s = np.asarray(scores, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"scores must be (n_objects, n_columns), got shape {s.shape}")
    n, c = s.shape
    if n == 0 or c == 0:
        raise ValueError(f"scores must have at least one object and one column, got {s.shape}")
    bad = ~np.isfinite(s)
    if bad.any():
        i, j = map(int, np.argwhere(bad)[0])
        raise ValueError(f"scores must be finite; object {i}, column {j} is {s[i, j]}")
    r = np.asarray(repeatable)
    if r.shape != (c,):
        raise ValueError(f"repeatable must have one entry per column, shape ({c},), got {r.shape}")
    if r.dtype != bool:
        raise ValueError(f"repeatable must be booleans, got {r.dtype.name}")
    if not r.any() and n > c:
        raise ValueError(
            f"{n} objects cannot take {c} columns one each, and no column is repeatable"
        )
    columns, total = _solve(s, r)
    alone = s.argmax(axis=1)
    margins = np.empty(n)
    for i in range(n):
        forbidden = np.zeros_like(s, dtype=bool)
        forbidden[i, columns[i]] = True
        other = _solve(s, r, forbidden)
        margins[i] = math.inf if other is None else max(0.0, total - other[1])
    return columns, alone, margins


def _solve(
    s: np.ndarray, repeatable: np.ndarray, forbidden: np.ndarray | None = None
) -> tuple[np.ndarray, float] | None:
    """(column of each object, summed score) of the best assignment avoiding ``forbidden``
    cells; None where no assignment avoids them."""
    n = len(s)
    index = np.r_[np.flatnonzero(~repeatable), np.repeat(np.flatnonzero(repeatable), n)]
    wide = s[:, index]
    if forbidden is not None:
        # far below any sum of real scores: chosen only where nothing else fits
        span = float(np.abs(s).max()) + 1.0
        wide = np.where(forbidden[:, index], -4.0 * span * (n + 1), wide)
    rows, picked = linear_sum_assignment(wide, maximize=True)
    columns = np.empty(n, np.int64)
    columns[rows] = index[picked]
    if forbidden is not None and forbidden[np.arange(n), columns].any():
        return None
    return columns, float(s[np.arange(n), columns].sum())


@dataclass
class TableScorer:
    """How ``name_table`` scores an object against every column (the module docstring).

    The defaults were chosen on development splits only (PHAC-2, split seeds 1 and 2, 10
    splits each, ``python -m bench.tables_phac2 development``,
    docs/results/tables/development/): mixed tables of 6 novel and 6 known objects, one
    touch each, ``gzsl_h`` 0.580 named jointly, the best with ``novelty_offset`` 0. An offset
    of 2 (objects on the threshold lean novel) reached 0.593 there, but it is a prior that
    half a table is novel: a table of known objects (the BioTac pilot's held-out trials)
    was then named novel throughout, where one by one they were right. With offset 0 an
    object alone is called known or novel exactly as the route calls it.

    Parameters
    ----------
    unregistered_prior : float, default 0.01
        Share of a novel object's probability kept for "none of the registered novel
        classes" (the repeatable ``UNREGISTERED`` column) where novel classes are
        registered. In (0, 1).
    novelty_slope : float, default 1.0
        Multiplies the fitted slope of P(novel) against the novelty score: above 1 trusts
        the novelty score more against the classes' probabilities. Positive.
    novel_temperature : float, default 4.0
        The novel classes' probabilities are raised to 1 / temperature and normalised again
        before the log (1: as the model gives them). Positive.
    novelty_offset : float, default 0.0
        Added to the logit of P(novel): above 0 an object on the routing threshold leans
        novel. Finite.
    floor : float, default 1e-4
        Probabilities are clipped to at least this before the log, so that a forest's 0
        stays a finite, large penalty. In (0, 0.5).
    """

    unregistered_prior: float = 0.01
    novelty_slope: float = 1.0
    novel_temperature: float = 4.0
    novelty_offset: float = 0.0
    floor: float = 1e-4

    def __post_init__(self) -> None:
        checks = {
            "unregistered_prior": 0.0 < self.unregistered_prior < 1.0,
            "novelty_slope": self.novelty_slope > 0 and math.isfinite(self.novelty_slope),
            "novel_temperature": self.novel_temperature > 0
            and math.isfinite(self.novel_temperature),
            "novelty_offset": math.isfinite(self.novelty_offset),
            "floor": 0.0 < self.floor < 0.5,
        }
        for name, ok in checks.items():
            if not ok:
                raise TableError(f"{name} is out of range: {getattr(self, name)!r}")

    def novel_probability(
        self, recognizer: Any, novelty: np.ndarray, threshold: float | np.ndarray
    ) -> np.ndarray:
        """P(novel) of each fused novelty score, centred on its routing ``threshold``."""
        slope = novelty_slope(recognizer.novelty_tuning)
        if slope is None:  # no held-out curves: the threshold's hard decision
            hard = np.asarray(novelty) > threshold
            return np.where(hard, 1.0 - self.floor, self.floor)
        logit = self.novelty_slope * slope * (np.asarray(novelty) - threshold)
        logit = logit + self.novelty_offset
        return 1.0 / (1.0 + np.exp(-np.clip(logit, -50, 50)))

    def scores(
        self,
        p_novel: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(log-scores (G, K + L + 1), repeatable (K + L + 1,)) of ``G`` fused objects over
        the known classes, the registered novel classes and ``UNREGISTERED``."""
        lo = self.floor
        pn = np.clip(p_novel, lo, 1.0 - lo)[:, None]
        known = np.log(np.clip(known_p, lo, 1.0))
        parts = [np.log1p(-pn) + known - known.max(axis=1, keepdims=True)]
        if novel_p is not None and novel_p.shape[1]:
            q = np.clip(novel_p, lo, 1.0) ** (1.0 / self.novel_temperature)
            q = q / q.sum(axis=1, keepdims=True)
            rest = math.log1p(-self.unregistered_prior)
            novel = np.concatenate(
                [
                    rest + np.log(np.clip(q, lo, 1.0)),
                    np.full((len(q), 1), math.log(self.unregistered_prior)),
                ],
                axis=1,
            )
            parts.append(np.log(pn) + novel - novel.max(axis=1, keepdims=True))
        else:
            parts.append(np.log(pn))
        scores = np.concatenate(parts, axis=1)
        repeatable = np.zeros(scores.shape[1], bool)
        repeatable[-1] = True
        return scores, repeatable


def novelty_slope(tuning: Any) -> float | None:
    """Slope of a logistic P(novel | score) fitted on the tuning's held-out curves (known
    and validation-novel scores, each class weighted to one half); None where the model
    holds no curve, or the curve cannot give one."""
    if tuning is None or len(tuning.thresholds) < 3:
        return None
    t = np.asarray(tuning.thresholds, np.float64)
    kept = np.asarray(tuning.known_kept, np.float64)
    val = np.asarray(tuning.val_novel, np.float64)
    # mass of each kind of score between consecutive thresholds, at their midpoint
    mid = (t[1:] + t[:-1]) / 2
    w_known, w_novel = np.diff(kept), -np.diff(val)
    x = np.r_[mid, mid]
    y = np.r_[np.zeros_like(mid), np.ones_like(mid)]
    w = np.r_[w_known / max(w_known.sum(), 1e-12), w_novel / max(w_novel.sum(), 1e-12)]
    keep = w > 0
    x, y, w = x[keep], y[keep], w[keep]
    if len(np.unique(y)) < 2:
        return None
    scale = float(np.std(x)) or 1.0
    xs = (x - x.mean()) / scale
    a, b = 0.0, 0.0  # Newton's method on the weighted log-loss, a little ridge
    for _ in range(50):
        p = 1.0 / (1.0 + np.exp(-np.clip(a * xs + b, -50, 50)))
        g = np.array([np.sum(w * (p - y) * xs) + 1e-3 * a, np.sum(w * (p - y))])
        h = w * p * (1 - p)
        hess = np.array([[np.sum(h * xs * xs) + 1e-3, np.sum(h * xs)], [np.sum(h * xs), h.sum()]])
        step = np.linalg.solve(hess + 1e-9 * np.eye(2), g)
        a, b = a - step[0], b - step[1]
        if np.abs(step).max() < 1e-8:
            break
    return float(a / scale) if a > 0 else None


def object_groups(
    objects: Sequence[Hashable], n: int, what: str = "sample"
) -> tuple[np.ndarray, list[Any]]:
    """(group of each of the ``n`` inputs, the distinct labels in first-appearance order);
    TableError for a wrong length or a label that cannot name an object. ``what``: the
    inputs' name in the messages ("sample", "trial")."""
    if isinstance(objects, str | bytes) or not hasattr(objects, "__len__"):
        raise TableError(f"objects must be a sequence of labels, one per {what}, got {objects!r}")
    if len(objects) != n:
        raise TableError(
            f"objects must give one label per {what}: {n} {what}s, {len(objects)} labels"
        )
    order: dict[Any, int] = {}
    group = np.empty(n, np.int64)
    for i, label in enumerate(objects):
        if isinstance(label, np.generic):
            label = label.item()
        if not isinstance(label, str | int) or isinstance(label, bool):
            raise TableError(
                f"objects[{i}] must be a string or an integer label, got {type(label).__name__}"
            )
        group[i] = order.setdefault(label, len(order))
    return group, list(order)


def _fused(recognizer: Any, samples: Any, objects: Sequence[Hashable], known_kept: float | None):
    """(label of each object, its rows, fused novelty, known and novel probabilities, its
    routing threshold)."""
    if recognizer.featurizer is not None and not isinstance(samples, np.ndarray):
        images, trial = recognizer.trial_samples(samples)
        by_input, labels = object_groups(objects, int(trial[-1]) + 1, "trial")
        x, used = recognizer._checked(images)
        group = by_input[trial]
        # an object fuses its trials: the curve of that many touches, as a same_object
        # answer to them reads (its images are not touches)
        touches = np.bincount(by_input, minlength=len(labels))
    else:
        touches = None
        x, used = recognizer._checked(samples)
        by_input, labels = object_groups(objects, len(x))
        group = by_input
    if used is None:
        novelty, known_p, novel_p = recognizer._all_scores(x)
    else:
        novelty, known_p, novel_p = recognizer._by_procedures(x, used, recognizer._scores_from)
    g = len(labels)
    single = (
        recognizer.novelty_threshold
        if known_kept is None
        else recognizer.threshold_keeping(known_kept)
    )
    fused = (
        group_mean(novelty, group, g),
        group_mean(known_p, group, g),
        None if novel_p is None else group_mean(novel_p, group, g),
    )
    threshold, _ = recognizer._thresholds(known_kept, single, group, g, touches)
    rows = [np.flatnonzero(by_input == j) for j in range(g)]
    return labels, rows, fused, threshold


def name_table(
    recognizer: Any,
    samples: Any,
    objects: Sequence[str | int],
    known_kept: float | None = None,
    scorer: TableScorer | None = None,
) -> tuple[list[TableAnswer], list[str | None]]:
    """Name the distinct objects of a table jointly (the module docstring).

    ``samples``: what ``recognize_batch`` takes (raw trials, as ``recognize_trials`` takes
    them, for a model fitted on raw trials); ``objects``: one label (str or int) per sample
    (per trial), equal labels for touches of the same object. ``known_kept``: the operating
    point of the routing threshold, as in ``recognize_batch``. ``scorer``: the scoring
    (``TableScorer()`` by default).

    Returns the answers, one per distinct object in first-appearance order, and the column
    names: the known classes, the registered novel classes, then ``UNREGISTERED`` (None).
    TableError for labels of the wrong length or kind, and more distinct objects than the
    table can name is never an error (``UNREGISTERED`` takes any number); the recognizer's
    own errors for bad samples.
    """
    scorer = scorer or TableScorer()
    labels, rows, (novelty, known_p, novel_p), threshold = _fused(
        recognizer, samples, objects, known_kept
    )
    p_novel = scorer.novel_probability(recognizer, novelty, threshold)
    scores, repeatable = scorer.scores(p_novel, known_p, novel_p)
    columns, alone, margins = assign_table(scores, repeatable)
    reg = recognizer.registry
    names: list[str | None] = [*reg.known_names, *reg.novel_names, UNREGISTERED]
    answers = [
        TableAnswer(
            object=label,
            rows=rows[j],
            column=int(columns[j]),
            alone=int(alone[j]),
            margin=float(margins[j]),
        )
        for j, label in enumerate(labels)
    ]
    return answers, names


def group_touches(recognizer: Any, samples: Any, n_objects: int, seed: int = 0) -> np.ndarray:
    """Object labels (0 … n_objects-1, first-appearance order) for unlabelled touches: k-means
    (``n_init`` 10, seeded) on each touch's score vector, its known-class and novel-class
    probabilities side by side. ``samples``: fixed-shape samples (for a raw-trial model,
    its images: ``trial_samples``). TableError where ``n_objects`` is not between 1 and the
    number of samples."""
    from sklearn.cluster import KMeans

    x, used = recognizer._checked(samples)
    if isinstance(n_objects, bool) or not isinstance(n_objects, int | np.integer):
        raise TableError(f"n_objects must be an integer, got {n_objects!r}")
    if not 1 <= int(n_objects) <= len(x):
        raise TableError(f"n_objects must lie in 1 … {len(x)} (the samples), got {n_objects}")
    if used is None:
        _, known_p, novel_p = recognizer._all_scores(x)
    else:
        _, known_p, novel_p = recognizer._by_procedures(x, used, recognizer._scores_from)
    features = known_p if novel_p is None else np.c_[known_p, novel_p]
    if int(n_objects) == 1:
        return np.zeros(len(x), np.int64)
    raw = KMeans(int(n_objects), n_init=10, random_state=int(seed)).fit_predict(features)
    _, first = np.unique(raw, return_index=True)
    order = np.argsort(np.argsort(first))  # cluster -> rank of its first sample
    return order[raw].astype(np.int64)
