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
