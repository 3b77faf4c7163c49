"""ND(x): novelty detection by a Gaussian mixture, and the Sect. VI-B threshold tuning.

A sample is novel when the fitted GMM's weighted log-likelihood of it is below
sigma_nov. Scores here are oriented "higher = more novel", so the score is the
negated log-likelihood and the threshold is -sigma_nov.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.special import logsumexp
from sklearn.decomposition import PCA
from sklearn.metrics import roc_auc_score
from sklearn.mixture import GaussianMixture

from app.data.dataset import DatasetError, TactileDataset
from app.framework.recognizer import NoveltyTuning


class GMMNoveltyDetector:
    """PCA to ``pca_dims`` (a full-covariance GMM cannot be fitted in 960-D from
    ~500 samples), then scikit-learn's GaussianMixture."""

    def __init__(
        self,
        n_components: int = 4,
        covariance_type: str = "full",
        pca_dims: int = 16,
        reg_covar: float = 1e-3,
        seed: int = 0,
    ) -> None:
        self.n_components = n_components
        self.covariance_type = covariance_type
        self.pca_dims = pca_dims
        self.reg_covar = reg_covar
        self.seed = seed
        self.pca_: PCA | None = None
        self.gmm_: GaussianMixture | None = None

    def fit(self, x: np.ndarray) -> GMMNoveltyDetector:
        x = x.reshape(len(x), -1)
        dims = min(self.pca_dims, x.shape[1], len(x) - 1)
        self.pca_ = PCA(n_components=dims, random_state=self.seed).fit(x)
        z = self.pca_.transform(x)
        k = min(self.n_components, len(x))
        self.gmm_ = GaussianMixture(
            k,
            covariance_type=self.covariance_type,
            reg_covar=self.reg_covar,
            random_state=self.seed,
            n_init=2,
        ).fit(z)
        return self

    def log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """Weighted log-likelihood log sum_k w_k N(x | mu_k, Sigma_k).

        Computed from the fitted parameters directly: the same value as
        ``GaussianMixture.score_samples``, without its per-call input validation,
        which costs more than the arithmetic for the service's single samples.
        """
        g, p = self.gmm_, self.pca_
        z = (x.reshape(len(x), -1) - p.mean_) @ p.components_.T
        chol = g.precisions_cholesky_
        if self.covariance_type == "full":
            y = np.einsum("nd,kde->nke", z, chol) - np.einsum("kd,kde->ke", g.means_, chol)[None]
            log_det = np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
        elif self.covariance_type == "diag":
            y = (z[:, None, :] - g.means_[None]) * chol[None]
            log_det = np.log(chol).sum(axis=1)
        else:
            return g.score_samples(z)
        log_prob = -0.5 * (z.shape[1] * np.log(2 * np.pi) + (y**2).sum(axis=2)) + log_det
        return logsumexp(log_prob + np.log(g.weights_), axis=1)

    def novelty_score(self, x: np.ndarray) -> np.ndarray:
        return -self.log_likelihood(x)

    def sklearn_log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """scikit-learn's own score_samples, kept as the reference the tests compare with."""
        return self.gmm_.score_samples(self.pca_.transform(x.reshape(len(x), -1)))

    # Stored as plain arrays so a bundle never needs pickle.
    def get_state(self) -> dict[str, np.ndarray]:
        g, p = self.gmm_, self.pca_
        return {
            "pca_mean": p.mean_,
            "pca_components": p.components_,
            "weights": g.weights_,
            "means": g.means_,
            "covariances": g.covariances_,
            "precisions_cholesky": g.precisions_cholesky_,
        }

    def set_state(self, a: dict[str, np.ndarray]) -> None:
        p = PCA(n_components=len(a["pca_components"]))
        p.mean_, p.components_ = a["pca_mean"], a["pca_components"]
        p.n_components_ = len(a["pca_components"])
        p.whiten = False
        g = GaussianMixture(len(a["weights"]), covariance_type=self.covariance_type)
        g.weights_, g.means_, g.covariances_ = a["weights"], a["means"], a["covariances"]
        g.precisions_cholesky_ = a["precisions_cholesky"]
        g.precisions_ = _precisions(a["precisions_cholesky"], self.covariance_type)
        g.converged_, g.n_iter_, g.lower_bound_ = True, 0, 0.0
        self.pca_, self.gmm_ = p, g


def _precisions(chol: np.ndarray, covariance_type: str) -> np.ndarray:
    if covariance_type == "full":
        return np.einsum("kij,klj->kil", chol, chol)
    if covariance_type == "tied":
        return chol @ chol.T
    return chol**2


def tune_threshold(
    known_scores: np.ndarray,
    novel_scores: np.ndarray,
    n_thresholds: int = 200,
    known_trials: np.ndarray | None = None,
) -> NoveltyTuning:
    """Pick the threshold that maximises the mean of the accuracy of calling known
    samples known and novel samples novel (Sect. VI-B, Fig. 7). With ``known_trials``
    ((N, 2): object and trial of each known score), the tuning also holds the curves of
    fused touches (``touch_curves``)."""
    known_scores = np.asarray(known_scores, np.float64)
    novel_scores = np.asarray(novel_scores, np.float64)
    if len(known_scores) == 0 or len(novel_scores) == 0:
        raise ValueError("threshold tuning needs both known and validation-novel samples")
    both = np.concatenate([known_scores, novel_scores])
    grid = np.unique(np.quantile(both, np.linspace(0, 1, n_thresholds)))
    # a sample is novel when its score is strictly above the threshold
    known_kept = (known_scores[None, :] <= grid[:, None]).mean(axis=1)
    val_novel = (novel_scores[None, :] > grid[:, None]).mean(axis=1)
    best = int(np.argmax(known_kept + val_novel))
    labels = np.r_[np.zeros(len(known_scores)), np.ones(len(novel_scores))]
    return NoveltyTuning(
        thresholds=grid,
        known_kept=known_kept,
        val_novel=val_novel,
        threshold=float(grid[best]),
        known_kept_at_threshold=float(known_kept[best]),
        val_novel_at_threshold=float(val_novel[best]),
        auroc=float(roc_auc_score(labels, both)),
        touches={}
        if known_trials is None
        else touch_curves(known_scores, known_trials, n_thresholds=n_thresholds),
    )


#: the most touches (trials) fused in a calibration curve; answers fusing more read this
#: one's (``NoveltyTuning.curve_for``)
MAX_TOUCHES = 5
#: fewer fused groups than this measure no curve: the answers read fewer touches' curve
MIN_GROUPS = 20
#: groups drawn per object and number of touches at most (all of them where fewer)
GROUPS_PER_OBJECT = 20


def touch_curves(
    known_scores: np.ndarray,
    known_trials: np.ndarray,
    max_touches: int = MAX_TOUCHES,
    n_thresholds: int = 200,
    seed: int = 0,
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """``{k: (thresholds, known_kept)}``: the calibration curves of answers fusing k touches
    of one known object, measured on held-out known scores. ``known_trials`` (N, 2): the
    object and trial of each score. A touch is a trial: the mean score of its samples (the
    images of a raw trial, the rounds that held the same trial out); a group of k touches is
    k distinct held-out trials of one object, its fused score their mean, as
    ``fuse_groups`` fuses an answer's. Every k-subset of an object's trials is a group where
    there are at most ``GROUPS_PER_OBJECT``, else that many drawn at random.

    k = 1 is the curve of whole trials: a raw-trial model's answer to one trial reads it (a
    model of samples reads its single samples' curve for one touch). A k with fewer than
    ``MIN_GROUPS`` groups ends the curves (answers fusing k touches or more then read the
    largest k measured)."""
    scores = np.asarray(known_scores, np.float64)
    ids = np.asarray(known_trials).reshape(len(scores), 2)
    trials, unit = np.unique(ids, axis=0, return_inverse=True)
    unit = unit.ravel()
    unit_score = np.bincount(unit, scores) / np.bincount(unit)
    objects = trials[:, 0]
    by_object = [unit_score[objects == o] for o in np.unique(objects)]
    rng = np.random.default_rng(seed)
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for k in range(1, max_touches + 1):
        fused = [_fused(own, k, rng) for own in by_object if len(own) >= k]
        fused = np.concatenate(fused) if fused else np.zeros(0)
        if len(fused) < MIN_GROUPS:
            break
        grid = np.unique(np.quantile(fused, np.linspace(0, 1, n_thresholds)))
        out[k] = (grid, (fused[None, :] <= grid[:, None]).mean(axis=1))
    return out


def _fused(own: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Mean scores of k-subsets of one object's touches ``own``: all of them where there
    are at most ``GROUPS_PER_OBJECT``, else that many drawn."""
    if math.comb(len(own), k) <= GROUPS_PER_OBJECT:
        subsets = np.array(list(itertools.combinations(range(len(own)), k)), np.int64)
    else:
        subsets = np.array(
            [rng.choice(len(own), k, replace=False) for _ in range(GROUPS_PER_OBJECT)]
        )
    return own[subsets].mean(axis=1)


def threshold_at_kept(
    known_scores: np.ndarray,
    novel_scores: np.ndarray,
    kept: float,
    n_thresholds: int = 200,
    known_trials: np.ndarray | None = None,
) -> NoveltyTuning:
    """The threshold that keeps the share ``kept`` of held-out known samples known (their
    scores' ``kept`` quantile): an operating point stated in advance rather than Sect. VI-B's
    balanced choice, whose known share moves with the validation objects. ``novel_scores``
    (validation-novel samples) only report what it detects there, and the AUROC;
    ``known_trials`` as ``tune_threshold``'s."""
    tuning = tune_threshold(known_scores, novel_scores, n_thresholds, known_trials)
    threshold = float(np.quantile(np.asarray(known_scores, np.float64), kept))
    return NoveltyTuning(
        thresholds=tuning.thresholds,
        known_kept=tuning.known_kept,
        val_novel=tuning.val_novel,
        threshold=threshold,
        known_kept_at_threshold=float((np.asarray(known_scores) <= threshold).mean()),
        val_novel_at_threshold=float((np.asarray(novel_scores) > threshold).mean()),
        auroc=tuning.auroc,
        touches=tuning.touches,
    )


def novelty_validation_split(
    dataset: TactileDataset, val_fraction: float = 0.1, holdout_trials: int = 1, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sect. VI-B: (fit_idx, known_heldout_idx, val_novel_idx) into ``dataset``.

    ``val_fraction`` of the classes (at least one) act as validation-novel objects;
    of each remaining class, ``holdout_trials`` whole trials are held out as known
    validation samples and the rest fit the detector.
    """
    rng = np.random.default_rng(seed)
    k = dataset.n_classes
    n_val = max(1, int(round(val_fraction * k)))
    if k - n_val < 1:
        raise DatasetError(f"novelty tuning needs at least 2 classes, got {k}")
    val_classes = rng.choice(k, size=n_val, replace=False)
    is_val = np.isin(dataset.labels, val_classes)
    # each (class, trial) pair once, sorted by class then trial: one sort, not a pass over
    # the samples per class
    pairs, pair_of_sample = np.unique(
        np.c_[dataset.labels, dataset.trials], axis=0, return_inverse=True
    )
    starts = np.searchsorted(pairs[:, 0], np.arange(k + 1))
    chosen_pairs = []
    for c in np.setdiff1d(np.arange(k), val_classes):
        trials = pairs[starts[c] : starts[c + 1], 1]
        if len(trials) > holdout_trials:
            chosen = rng.choice(trials, size=holdout_trials, replace=False)
            chosen_pairs.append(starts[c] + np.searchsorted(trials, chosen))
    heldout = np.zeros(len(dataset), dtype=bool)
    if chosen_pairs:
        heldout = np.isin(pair_of_sample.ravel(), np.concatenate(chosen_pairs))
    fit = ~is_val & ~heldout
    return np.flatnonzero(fit), np.flatnonzero(heldout), np.flatnonzero(is_val)
