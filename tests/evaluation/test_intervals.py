"""Confidence intervals over splits, paired differences and the oracle novelty threshold, on
fixed numbers whose answers are known (scipy's t distribution, brute force)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from app.evaluation import metrics
from app.evaluation.protocol import paired_entry, paired_summary, summarize_entry

VALUES = [0.61, 0.55, 0.72, 0.58, 0.66, 0.49, 0.70]


def test_mean_interval_is_scipys_t_interval():
    low, high = metrics.mean_interval(VALUES)
    ref = stats.t.interval(
        0.95, len(VALUES) - 1, loc=np.mean(VALUES), scale=stats.sem(VALUES)
    )  # sem: sample standard deviation (ddof 1) / sqrt(n)
    assert (low, high) == pytest.approx(ref, abs=1e-12)
    # by hand: t(0.975, 6) = 2.446912
    half = 2.446912 * np.std(VALUES, ddof=1) / math.sqrt(len(VALUES))
    assert high - low == pytest.approx(2 * half, rel=1e-6)
    # clipped to the range of a fraction, NaN ignored, undefined below two values
    assert metrics.mean_interval([0.99, 1.0, 0.97], bounds=(0.0, 1.0))[1] == 1.0
    assert metrics.mean_interval([*VALUES, math.nan]) == (low, high)
    assert all(math.isnan(v) for v in metrics.mean_interval([0.5]))


def test_summarize_entry_gives_every_figure_its_interval():
    entry = {"splits": [{"split": i + 1, "zsl": v, "osl": 1.0} for i, v in enumerate(VALUES)]}
    summarize_entry(entry, ["zsl", "osl", "gzsl_h"])
    assert entry["mean"]["zsl"] == pytest.approx(np.mean(VALUES))
    assert entry["std"]["zsl"] == pytest.approx(np.std(VALUES))  # ddof 0, the first layout's
    ref = stats.t.interval(0.95, len(VALUES) - 1, loc=np.mean(VALUES), scale=stats.sem(VALUES))
    assert entry["ci95"]["zsl"] == pytest.approx(list(ref), abs=1e-12)
    assert entry["ci95"]["osl"] == [1.0, 1.0]  # no spread: a zero-width interval
    assert math.isnan(entry["mean"]["gzsl_h"])  # a figure no split has
    assert all(math.isnan(v) for v in entry["ci95"]["gzsl_h"])


def _entry(values):
    entry = {"splits": [{"split": i + 1, "zsl": v} for i, v in enumerate(values)]}
    summarize_entry(entry, ["zsl"])
    return entry


def test_paired_differences_against_known_numbers():
    other = [
        v + d for v, d in zip(VALUES, [0.02, -0.01, 0.05, 0.0, 0.03, 0.04, -0.02], strict=True)
    ]
    p = paired_entry(_entry(other), _entry(VALUES))
    d = np.subtract(other, VALUES)
    assert p["splits"]["zsl"] == pytest.approx(d.tolist())
    assert p["mean"]["zsl"] == pytest.approx(d.mean())
    ref = stats.t.interval(0.95, len(d) - 1, loc=d.mean(), scale=stats.sem(d))
    assert p["ci95"]["zsl"] == pytest.approx(list(ref), abs=1e-12)
    assert p["won"]["zsl"] == 4 and p["lost"]["zsl"] == 2  # one split tied
    # pairing removes the split-to-split spread both methods share
    own = _entry(other)["ci95"]["zsl"]
    assert p["ci95"]["zsl"][1] - p["ci95"]["zsl"][0] < (own[1] - own[0]) / 2
    assert metrics.paired_differences([0.5, math.nan], [0.25, 0.1])[0] == 0.25
    assert math.isnan(metrics.paired_differences([0.5, math.nan], [0.25, 0.1])[1])
    with pytest.raises(ValueError, match="length"):
        metrics.paired_differences([0.5], [0.5, 0.6])


def test_a_method_against_itself_differs_by_exactly_zero():
    entry = _entry(VALUES)
    p = paired_entry(entry, entry)
    assert p["splits"]["zsl"] == [0.0] * len(VALUES)
    assert p["mean"]["zsl"] == 0.0 and p["ci95"]["zsl"] == [0.0, 0.0]
    assert p["won"]["zsl"] == 0 and p["lost"]["zsl"] == 0
    # paired_summary leaves the reference itself out
    both = paired_summary({"a": entry, "b": _entry(VALUES)}, "a")
    assert both["reference"] == "a" and list(both["methods"]) == ["b"]
    assert both["methods"]["b"]["mean"]["zsl"] == 0.0


def test_paired_differences_need_the_same_splits():
    a = _entry(VALUES)
    with pytest.raises(ValueError, match="same splits"):
        paired_entry(_entry(VALUES[:3]), a)
    shuffled = _entry(VALUES)
    shuffled["splits"] = shuffled["splits"][::-1]
    with pytest.raises(ValueError, match="same order"):
        paired_entry(shuffled, a)


def test_oracle_threshold_on_a_known_case():
    # threshold 0.3: 3 of 4 known kept, 3 of 3 novel detected -> min 0.75, the best there is
    # (0.6 keeps every known sample but detects 2 of 3: min 0.667)
    threshold, kept, detected = metrics.oracle_threshold([0.1, 0.2, 0.3, 0.6], [0.5, 0.7, 0.8])
    assert threshold == 0.3 and kept == 0.75 and detected == 1.0
    # fully separated: everything right; fully inverted: the best balance is 0.5
    assert metrics.oracle_threshold([0.1, 0.2], [0.8, 0.9])[1:] == (1.0, 1.0)
    _, kept, detected = metrics.oracle_threshold([0.8, 0.9], [0.1, 0.2])
    assert min(kept, detected) == 0.0
    with pytest.raises(ValueError):
        metrics.oracle_threshold([], [0.1])


def test_oracle_threshold_beats_every_threshold_on_random_scores():
    rng = np.random.default_rng(3)
    known, novel = rng.normal(0, 1, 80), rng.normal(1.5, 1, 45)
    threshold, kept, detected = metrics.oracle_threshold(known, novel)
    assert kept == np.mean(known <= threshold) and detected == np.mean(novel > threshold)
    grid = np.linspace(-5, 6, 20001)
    brute = max(min(np.mean(known <= t), np.mean(novel > t)) for t in grid)
    assert min(kept, detected) == pytest.approx(brute)
    for t in grid[::50]:
        assert min(kept, detected) >= min(np.mean(known <= t), np.mean(novel > t))


def _long_tailed(rng: np.random.Generator, size: int) -> np.ndarray:
    """Per-split figures like PHAC-2's novelty detection: most splits near 0.94, one in 20
    far below (a threshold tuned badly on that split's validation objects)."""
    tail = rng.random(size) < 0.05
    return np.where(tail, rng.uniform(0.5, 0.8, size), rng.normal(0.94, 0.03, size))


def _coverage(law, base_size: int, runs: int, seed: int) -> tuple[float, float]:
    """How often a 50-split re-run's mean lands in the published run's confidence interval
    and in its re-run interval, the published run having ``base_size`` splits."""
    rng = np.random.default_rng(seed)
    caught_ci = caught_rerun = 0
    for _ in range(runs):
        published = law(rng, base_size)
        rerun_mean = law(rng, 50).mean()
        lo, hi = metrics.mean_interval(published)
        caught_ci += lo <= rerun_mean <= hi
        lo, hi = metrics.rerun_interval(published, rerun_size=50, draws=1_000, seed=1)
        caught_rerun += lo <= rerun_mean <= hi
    return caught_ci / runs, caught_rerun / runs


def test_rerun_interval_catches_reruns_where_the_confidence_interval_does_not():
    # a 95 % confidence interval holds the true mean but misses many re-runs' means, since
    # those move too (~0.83 of same-sized re-runs caught under a normal law); the re-run
    # interval is built to hold them
    ci, rerun = _coverage(lambda rng, n: rng.normal(0.5, 0.1, n), 50, runs=300, seed=7)
    assert ci < 0.89
    assert 0.91 <= rerun <= 0.99
    # a long-tailed figure needs a long base: 500 splits show the tail often enough
    ci, rerun = _coverage(_long_tailed, 500, runs=150, seed=7)
    assert ci < 0.6  # a 500-split confidence interval is far narrower than a re-run's spread
    assert 0.91 <= rerun <= 1.0


def test_rerun_interval_for_a_smaller_rerun_from_a_long_base():
    # a 500-split base predicting a 50-split re-run: wider than the base's own confidence
    # interval, about t * s * sqrt(1/500 + 1/50) on each side, and longer below (the tail)
    rng = np.random.default_rng(3)
    base = _long_tailed(rng, 500)
    lo, hi = metrics.rerun_interval(base, rerun_size=50, seed=0)
    mean, s = base.mean(), base.std(ddof=1)
    half = stats.t.ppf(0.975, 499) * s * math.sqrt(1 / 500 + 1 / 50)
    assert lo <= mean - half and hi >= mean + half  # never narrower than the t interval
    assert mean - lo > hi - mean  # the long lower tail shows
    assert (mean - lo) < 1.5 * half
    ci = metrics.mean_interval(base)
    assert lo < ci[0] and hi > ci[1]
    # reproducible, NaN ignored, undefined below two values, bad arguments named
    assert metrics.rerun_interval(base, rerun_size=50, seed=0) == (lo, hi)
    assert metrics.rerun_interval([*base, math.nan], rerun_size=50, seed=0) == (lo, hi)
    assert all(math.isnan(v) for v in metrics.rerun_interval([0.5]))
    with pytest.raises(ValueError, match="rerun_size"):
        metrics.rerun_interval(base, rerun_size=0)
    with pytest.raises(ValueError, match="level"):
        metrics.rerun_interval(base, level=1.0)


def test_summarize_entry_gives_every_figure_its_rerun_range():
    entry = {"splits": [{"split": i + 1, "zsl": v} for i, v in enumerate(VALUES)]}
    summarize_entry(entry, ["zsl"], rerun_splits=20)
    lo, hi = entry["rerun95"]["zsl"]
    assert (lo, hi) == metrics.rerun_interval(VALUES, 20, bounds=(0.0, 1.0))
    ci = entry["ci95"]["zsl"]
    assert lo < ci[0] < ci[1] < hi
