"""The figures of Sect. VI as plain functions of arrays; every result is a fraction in [0, 1]."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sklearn.metrics import roc_auc_score

#: the figures of one model on a mixed test of known and novel objects, as the touches and
#: procedures measurements repeat them for each number of touches or set of procedures
MIXED_FIGURES: tuple[str, ...] = (
    "known_acc",
    "nd_known_kept",
    "nd_novel_detected",
    "zsl",
    "gzsl_seen",
    "gzsl_unseen",
    "gzsl_h",
)


def accuracy(y_true: Sequence, y_pred: Sequence) -> float:
    """Fraction of equal entries (labels may be ints or class names)."""
    t = np.asarray(y_true)
    p = np.asarray(y_pred)
    if t.shape != p.shape:
        raise ValueError(f"y_true {t.shape} and y_pred {p.shape} differ in shape")
    if t.size == 0:
        raise ValueError("accuracy of an empty set is undefined")
    return float(np.mean(t == p))


def argmax_accuracy(proba: np.ndarray, y_true: Sequence[int]) -> float:
    """Accuracy of the most probable column of ``proba`` (N, K) against integer labels."""
    proba = np.asarray(proba)
    if proba.ndim != 2 or len(proba) != len(y_true):
        raise ValueError(f"proba must be (N, K) with N={len(y_true)}, got {proba.shape}")
    return accuracy(np.asarray(y_true), proba.argmax(axis=1))


def detection_rate(scores: Sequence[float], threshold: float) -> float:
    """Fraction of samples called novel: novelty score strictly above the threshold."""
    s = np.asarray(scores, dtype=np.float64)
    if s.size == 0:
        raise ValueError("detection rate of an empty set is undefined")
    return float(np.mean(s > threshold))


def novelty_auroc(known_scores: Sequence[float], novel_scores: Sequence[float]) -> float:
    """AUROC of separating novel (positive) from known samples by score (higher = more novel)."""
    k = np.asarray(known_scores, dtype=np.float64)
    n = np.asarray(novel_scores, dtype=np.float64)
    if k.size == 0 or n.size == 0:
        raise ValueError("AUROC needs at least one known and one novel score")
    y = np.concatenate([np.zeros(k.size), np.ones(n.size)])
    return float(roc_auc_score(y, np.concatenate([k, n])))


def harmonic_mean(a: float, b: float) -> float:
    """2ab / (a + b); 0 when both are 0 (the GZSL 'H' figure)."""
    if a < 0 or b < 0:
        raise ValueError(f"harmonic mean of negative values {a}, {b}")
    return 0.0 if a + b == 0 else float(2 * a * b / (a + b))


def confusion_matrix(y_true: Sequence[int], y_pred: Sequence[int], n_classes: int) -> np.ndarray:
    """Counts: row = true class, column = predicted class."""
    t = np.asarray(y_true, dtype=np.int64)
    p = np.asarray(y_pred, dtype=np.int64)
    if t.shape != p.shape:
        raise ValueError("y_true and y_pred differ in shape")
    if t.size and (min(t.min(), p.min()) < 0 or max(t.max(), p.max()) >= n_classes):
        raise ValueError(f"labels must lie in [0, {n_classes})")
    cm = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(cm, (t, p), 1)
    return cm


def row_normalize(cm: np.ndarray) -> np.ndarray:
    """Each row divided by its sum (rows that sum to 0 stay 0)."""
    cm = np.asarray(cm, dtype=np.float64)
    sums = cm.sum(axis=1, keepdims=True)
    return np.divide(cm, sums, out=np.zeros_like(cm), where=sums > 0)


def jaccard_similarity(vectors: np.ndarray) -> np.ndarray:
    """Pairwise Jaccard similarity |a ∧ b| / |a ∨ b| of 0/1 attribute vectors (Fig. 8d).

    Two empty vectors are defined as identical (similarity 1).
    """
    v = np.asarray(vectors) > 0.5
    if v.ndim != 2:
        raise ValueError(f"expected a (L, M) matrix of attribute vectors, got shape {v.shape}")
    vi = v.astype(np.int64)
    inter = vi @ vi.T
    union = v.sum(axis=1)[:, None] + v.sum(axis=1)[None, :] - inter
    return np.divide(inter, union, out=np.ones(inter.shape, np.float64), where=union > 0)


def gzsl_figures(
    true_names: Sequence[str], pred_names: Sequence[str], is_known: Sequence[bool]
) -> dict[str, float]:
    """Mixed known/novel test set: accuracy on the known part, the novel part, and their H."""
    t = np.asarray(true_names, dtype=object)
    p = np.asarray(pred_names, dtype=object)
    k = np.asarray(is_known, dtype=bool)
    if not (len(t) == len(p) == len(k)):
        raise ValueError("true names, predictions and kinds must have the same length")
    if k.all() or not k.any():
        raise ValueError("the mixed test set needs both known and novel samples")
    seen = accuracy(t[k], p[k])
    unseen = accuracy(t[~k], p[~k])
    return {"gzsl_seen": seen, "gzsl_unseen": unseen, "gzsl_h": harmonic_mean(seen, unseen)}


def summarize(values: Sequence[float]) -> tuple[float, float]:
    """(mean, standard deviation) ignoring NaN; (nan, nan) when nothing is finite."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std())


def mean_interval(
    values: Sequence[float], level: float = 0.95, bounds: tuple[float, float] | None = None
) -> tuple[float, float]:
    """Confidence interval of the mean of ``values`` (Student's t with n - 1 degrees of
    freedom and the sample standard deviation), ignoring NaN; (nan, nan) with fewer than 2
    finite values. ``bounds``: the range the mean cannot leave (0 and 1 for a fraction),
    which clips the interval. The values are taken as independent draws: for figures of
    repeated random splits, which share data, the interval is narrower than the true
    uncertainty."""
    from scipy.stats import t as student_t

    v = _finite(values, level)
    if v.size < 2:
        return float("nan"), float("nan")
    half = float(student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))
    mean = float(v.mean())
    return _clipped(mean - half, mean + half, bounds)


def _finite(values: Sequence[float], level: float) -> np.ndarray:
    """The finite ``values`` as float64, after checking ``level`` (an interval's)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    v = np.asarray(values, dtype=np.float64)
    return v[np.isfinite(v)]


def _clipped(low: float, high: float, bounds: tuple[float, float] | None) -> tuple[float, float]:
    if bounds is None:
        return low, high
    return max(low, bounds[0]), min(high, bounds[1])


def rerun_interval(
    values: Sequence[float],
    rerun_size: int | None = None,
    level: float = 0.95,
    bounds: tuple[float, float] | None = None,
    draws: int = 20_000,
    seed: int = 0,
) -> tuple[float, float]:
    """Where the mean of a re-run lands: a bootstrap prediction interval for the mean of
    ``rerun_size`` new values (default: as many as ``values``) drawn like ``values``,
    ignoring NaN; (nan, nan) with fewer than 2 finite values.

    A confidence interval of the mean holds the true mean, not another run's mean: under a
    normal law a 95 % one catches a same-sized re-run only ~83 % of the time, since both
    means move. Here each of ``draws`` bootstrap rounds resamples ``values`` twice, once at
    their own size and once at ``rerun_size``, and the interval is the mean plus the
    ``(1 ± level) / 2`` quantiles of (re-run mean − own mean): it counts both sources of
    noise, and keeps the skew of a figure whose splits have a long tail (a few splits far
    below the rest), which a symmetric t interval hides. Each side is the wider of that and
    the Student-t prediction interval (mean ± t · s · sqrt(1/n + 1/rerun_size)), since
    resampling a few values understates their spread. It cannot know of tails
    ``values`` never showed, so it is only as good as the splits behind it. ``seed`` fixes
    the resampling, so the interval is reproducible. ``bounds`` clips it."""
    v = _finite(values, level)
    if v.size < 2:
        return float("nan"), float("nan")
    m = v.size if rerun_size is None else int(rerun_size)
    if m < 1:
        raise ValueError(f"rerun_size must be a positive integer, got {rerun_size!r}")
    rng = np.random.default_rng(seed)
    own = np.empty(draws)
    rerun = np.empty(draws)
    # chunks keep the index arrays small for a long base (500 splits x 20,000 draws)
    step = max(1, 2_000_000 // max(v.size, m))
    for start in range(0, draws, step):
        stop = min(draws, start + step)
        own[start:stop] = v[rng.integers(0, v.size, (stop - start, v.size))].mean(axis=1)
        rerun[start:stop] = v[rng.integers(0, v.size, (stop - start, m))].mean(axis=1)
    low_q, high_q = np.quantile(rerun - own, [(1 - level) / 2, (1 + level) / 2])
    # the t prediction interval, for few values, where resampling them understates the spread
    from scipy.stats import t as student_t

    half = float(
        student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) * np.sqrt(1 / v.size + 1 / m)
    )
    mean = float(v.mean())
    return _clipped(mean + min(float(low_q), -half), mean + max(float(high_q), half), bounds)


def wilson_interval(fraction: float, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a success fraction measured on ``n`` independent trials:
    how far an accuracy on ``n`` test trials may be from the accuracy on all such trials."""
    from scipy.stats import norm

    if n < 1 or not 0.0 <= fraction <= 1.0:
        raise ValueError(f"need n >= 1 and a fraction in [0, 1], got {fraction} of {n}")
    z = float(norm.ppf(0.5 + level / 2))
    centre = (fraction + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * np.sqrt(fraction * (1 - fraction) / n + z * z / (4 * n * n))
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def paired_differences(values: Sequence[float], reference: Sequence[float]) -> list[float]:
    """``values[i] - reference[i]`` per split (the same splits, in the same order); NaN
    where either is not finite."""
    a = np.asarray(values, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired values differ in length: {a.shape} and {b.shape}")
    d = a - b
    d[~(np.isfinite(a) & np.isfinite(b))] = np.nan
    return d.tolist()


def oracle_threshold(
    known_scores: Sequence[float], novel_scores: Sequence[float]
) -> tuple[float, float, float]:
    """The best threshold for telling these novel samples from these known ones, chosen on
    the samples themselves: (threshold, known kept, novel detected) at the threshold that
    maximises min(share of known scores at or below it, share of novel scores above it),
    ties broken by the larger sum of the two, then by the lower threshold. No threshold
    tuned without the samples can do better on both at once: a measured upper bound on
    novelty detection by this score."""
    k = np.sort(np.asarray(known_scores, dtype=np.float64))
    n = np.sort(np.asarray(novel_scores, dtype=np.float64))
    if k.size == 0 or n.size == 0:
        raise ValueError("the oracle threshold needs at least one known and one novel score")
    # every distinct score, and one below them all (every sample called novel)
    candidates = np.unique(np.concatenate([k, n]))
    candidates = np.concatenate([[np.nextafter(candidates[0], -np.inf)], candidates])
    kept = np.searchsorted(k, candidates, side="right") / k.size
    detected = 1.0 - np.searchsorted(n, candidates, side="right") / n.size
    balance = np.minimum(kept, detected)
    best = np.flatnonzero(balance == balance.max())
    i = int(best[np.argmax((kept + detected)[best])])  # argmax: the first (lowest) of ties
    return float(candidates[i]), float(kept[i]), float(detected[i])
