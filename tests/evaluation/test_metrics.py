"""Metric functions on hand-made cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.evaluation import metrics as m


def test_accuracy_and_argmax_accuracy():
    assert m.accuracy([0, 1, 2, 2], [0, 1, 1, 2]) == 0.75
    assert m.accuracy(["a", "b"], ["a", "c"]) == 0.5
    proba = np.array([[0.9, 0.1], [0.2, 0.8], [0.6, 0.4]])
    assert m.argmax_accuracy(proba, [0, 1, 1]) == pytest.approx(2 / 3)
    with pytest.raises(ValueError):
        m.accuracy([], [])
    with pytest.raises(ValueError):
        m.accuracy([1, 2], [1])


def test_detection_rate_is_strictly_above_threshold():
    assert m.detection_rate([0.1, 0.5, 0.9, 0.5], 0.5) == 0.25


def test_novelty_auroc_known_values():
    assert m.novelty_auroc([0.1, 0.2], [0.8, 0.9]) == 1.0
    assert m.novelty_auroc([0.8, 0.9], [0.1, 0.2]) == 0.0
    assert m.novelty_auroc([0.5, 0.5], [0.5]) == 0.5
    # pairs (novel > known): 0.35>0.1 yes, 0.35>0.4 no, 0.8 beats both -> 3/4
    assert m.novelty_auroc([0.1, 0.4], [0.35, 0.8]) == 0.75


def test_harmonic_mean():
    assert m.harmonic_mean(0.5, 1.0) == pytest.approx(2 / 3)
    assert m.harmonic_mean(0.0, 0.0) == 0.0
    assert m.harmonic_mean(0.0, 0.9) == 0.0
    assert m.harmonic_mean(0.6, 0.6) == pytest.approx(0.6)


def test_confusion_matrix_and_row_normalize():
    cm = m.confusion_matrix([0, 0, 1, 2, 2, 2], [0, 1, 1, 2, 0, 2], 3)
    assert cm.tolist() == [[1, 1, 0], [0, 1, 0], [1, 0, 2]]
    assert np.allclose(m.row_normalize(cm), [[0.5, 0.5, 0], [0, 1, 0], [1 / 3, 0, 2 / 3]])
    assert m.row_normalize(np.zeros((2, 2))).tolist() == [[0, 0], [0, 0]]
    with pytest.raises(ValueError):
        m.confusion_matrix([0, 3], [0, 0], 3)


def test_jaccard_similarity():
    v = np.array([[1, 1, 0], [0, 1, 1], [1, 1, 0], [0, 0, 1]])
    j = m.jaccard_similarity(v)
    assert j[0, 1] == pytest.approx(1 / 3)
    assert j[0, 2] == 1.0 and j[0, 3] == 0.0 and j[1, 3] == 0.5
    assert np.allclose(np.diag(j), 1) and np.allclose(j, j.T)


def test_gzsl_figures():
    f = m.gzsl_figures(["a", "b", "x", "y"], ["a", "a", "x", "x"], [True, True, False, False])
    assert f == {"gzsl_seen": 0.5, "gzsl_unseen": 0.5, "gzsl_h": 0.5}
    f = m.gzsl_figures(["a", "x", "y"], ["a", "a", "y"], [True, False, False])
    assert f["gzsl_seen"] == 1.0 and f["gzsl_unseen"] == 0.5 and f["gzsl_h"] == pytest.approx(2 / 3)
    with pytest.raises(ValueError, match="both"):
        m.gzsl_figures(["a"], ["a"], [True])


def test_summarize_ignores_nan():
    assert m.summarize([0.2, float("nan"), 0.4]) == pytest.approx((0.3, 0.1))
    mean, std = m.summarize([float("nan")])
    assert np.isnan(mean) and np.isnan(std)
