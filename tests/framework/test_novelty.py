"""Novelty detection: GMM scores, threshold tuning (Sect. VI-B), validation split."""

import numpy as np
import pytest

from app.framework.novelty import GMMNoveltyDetector, novelty_validation_split, tune_threshold


def test_tune_threshold_separates_separable_scores():
    tuning = tune_threshold(np.array([0.0, 1.0, 2.0]), np.array([5.0, 6.0]))
    assert 2.0 <= tuning.threshold < 5.0
    assert tuning.known_kept_at_threshold == 1.0
    assert tuning.val_novel_at_threshold == 1.0
    assert tuning.auroc == 1.0


def test_tune_threshold_balances_overlapping_scores():
    known = np.array([0.0, 1.0, 2.0, 3.0])
    novel = np.array([2.5, 4.0, 5.0, 6.0])
    t = tune_threshold(known, novel)
    assert t.known_kept_at_threshold + t.val_novel_at_threshold == pytest.approx(1.75)
    # very low thresholds call everything novel, very high ones everything known (Fig. 7)
    assert t.known_kept[0] < 0.5 and t.val_novel[-1] == 0.0


def test_tune_threshold_needs_both_sides():
    with pytest.raises(ValueError, match="both known and validation-novel"):
        tune_threshold(np.array([1.0]), np.array([]))


def test_gmm_scores_far_samples_as_more_novel_and_round_trips():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 10))
    det = GMMNoveltyDetector(n_components=2, pca_dims=5).fit(x)
    near, far = det.novelty_score(x[:50]), det.novelty_score(x[:50] + 6.0)
    assert (far > near).mean() > 0.95
    clone = GMMNoveltyDetector(n_components=2, pca_dims=5)
    clone.set_state(det.get_state())
    np.testing.assert_allclose(clone.novelty_score(x[:20]), det.novelty_score(x[:20]), rtol=1e-6)


def test_validation_split_follows_sect_vi_b(sim_split):
    ds = sim_split["train"]
    fit, known, val = novelty_validation_split(ds, val_fraction=0.1, holdout_trials=1, seed=1)
    assert len(np.intersect1d(fit, known)) == len(np.intersect1d(fit, val)) == 0
    val_classes = np.unique(ds.labels[val])
    assert len(val_classes) == 3  # 10 % of 30 known objects act as novel
    assert not np.isin(ds.labels[fit], val_classes).any()
    assert not np.isin(ds.trials[fit], ds.trials[known]).any()  # held out by whole trials
    assert len(known) == 27  # one trial of each fitting object


@pytest.mark.parametrize("cov", ["full", "diag"])
def test_direct_log_likelihood_equals_scikit_learns(cov):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(200, 12)) * rng.uniform(0.5, 3, size=12)
    det = GMMNoveltyDetector(n_components=3, covariance_type=cov, pca_dims=6).fit(x)
    probe = np.concatenate([x[:20], x[:20] * 4])
    np.testing.assert_allclose(
        det.log_likelihood(probe), det.sklearn_log_likelihood(probe), rtol=1e-9
    )
