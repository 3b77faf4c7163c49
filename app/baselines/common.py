"""What the baselines share: robust scaling, an extra-trees known-class classifier whose
max-probability is the novelty score, threshold tuning by Sect. VI-B, one-shot
nearest class means, and the carving of validation objects for hyper-parameters.

A baseline sees every sample as a flat vector (a C × T tactile image is
flattened), robust-scaled by ``RobustInputScaler`` (sign(x)·log1p|x|, median and
IQR, clipped): PHAC-2's static features reach 1e10 and have heavy tails.

Known classes: ``ExtraTreesClassifier`` on the scaled inputs; ``known_proba`` is its
``predict_proba``. Novelty score: 1 − max known probability (higher = more novel).
Its threshold is tuned by the paper's protocol: ``novelty_validation_split`` keeps
90% of the known objects to fit a probe forest, the other 10% act as
validation-novel objects and one held-out trial of every fitting object acts as
known; ``tune_threshold`` picks the threshold. The deployed forest is then fitted
on all known classes and keeps that threshold (as the paper's GMM does).

Novel classes: a subclass supplies the zero-shot posterior ``_zsl_proba``. One-shot
samples turn it into a nearest-class-mean (NCM) classifier: for the novel classes
that have real samples, p(c | x) ∝ exp(−‖x − μ_c‖ / τ) with μ_c the mean of the
class's scaled real samples and τ the median distance of training samples to
their own class mean; the zero-shot posterior decides how much mass goes to the
classes without samples (so with a sample for every class it is pure NCM, and
with none it is pure zero-shot).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.ensemble import ExtraTreesClassifier
from threadpoolctl import threadpool_limits

from app.data.dataset import DatasetError, TactileDataset
from app.evaluation.splits import SplitError, draw_novel_sets, novel_candidates
from app.framework.errors import FrameworkError
from app.framework.novelty import novelty_validation_split, tune_threshold
from app.framework.params import at_least, between
from app.framework.recognizer import TactileRecognizer
from app.framework.scaling import RobustInputScaler, flatten
from app.methods.attributes import softmax


class ForestBaseline(TactileRecognizer):
    """Base of the baselines; subclasses implement the zero-shot part (``_fit_zsl``,
    ``_prepare_novel``, ``_zsl_proba``) and take these parameters after their own.

    Parameters
    ----------
    n_estimators : int, default 300
        Trees in the extra-trees forest that classifies the known objects (its
        max-probability is the novelty score), and in the probe forest of the novelty
        tuning. At least 1.
    max_features : {"sqrt", "log2"} or float, default "sqrt"
        Features each split of a tree draws from, as scikit-learn's
        ``ExtraTreesClassifier`` takes it.
    min_samples_leaf : int, default 1
        Fewest training samples in a leaf of those trees. At least 1.
    novelty_val_fraction : float, default 0.1
        Share of the known objects that act as validation-novel objects (Y_val of
        Sect. VI-B) when the novelty threshold is tuned. In (0, 1).
    novelty_holdout_trials : int, default 1
        Whole trials of every other known object held out as its known validation
        samples (X_te of Sect. VI-B) in that tuning. At least 1.
    seed : int, default 0
        Seed of the forests, of the choice of validation objects for the novelty
        threshold, and of the validation folds that choose zero-shot settings.
    n_jobs : int or None, default -1
        Parallel jobs of scikit-learn's forests (-1: every core, None: one).
    featurizer_params : dict or None, default None
        Options of the ``TactileImageFeaturizer`` fitted when ``fit`` is given raw BioTac
        trials (``app.framework.tactile_image.featurizer_from_params``); an option left out
        (all of them with None) takes the featurizer's default, except ``n_offsets``, 1
        here: each training finger once (as ``best``; sub-sampling augmentation made the
        extra-trees forest worse across grip pressures on the BioTac pilot's validation
        trials, docs/RESULTS.md). Unused for fixed-shape samples.

    Fitted on classes without attributes (M = 0), a baseline recognises its known
    classes and detects novelty; it has no zero-shot part (enrolment is refused).
    """

    method = "forest-baseline"
    _featurizer_defaults = {"n_offsets": 1}  # see featurizer_params

    _parameter_constraints = {
        "n_estimators": at_least(1),
        "min_samples_leaf": at_least(1),
        "novelty_val_fraction": between(0, 1),
        "novelty_holdout_trials": at_least(1),
    }

    def __init__(
        self,
        n_estimators: int = 300,
        max_features: str | float = "sqrt",
        min_samples_leaf: int = 1,
        novelty_val_fraction: float = 0.1,
        novelty_holdout_trials: int = 1,
        seed: int = 0,
        n_jobs: int | None = -1,
        featurizer_params: dict[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.n_estimators = n_estimators
        self.max_features = max_features
        self.min_samples_leaf = min_samples_leaf
        self.novelty_val_fraction = novelty_val_fraction
        self.novelty_holdout_trials = novelty_holdout_trials
        self.seed = seed
        self.n_jobs = n_jobs
        self.featurizer_params = featurizer_params

    # ------------------------------------------------------------------ parts
    def _forest(self) -> ExtraTreesClassifier:
        return ExtraTreesClassifier(
            n_estimators=int(self.n_estimators),
            max_features=self.max_features,
            min_samples_leaf=int(self.min_samples_leaf),
            random_state=int(self.seed),
            n_jobs=self.n_jobs,
        )

    @staticmethod
    def _max_prob_score(forest: ExtraTreesClassifier, z: np.ndarray) -> np.ndarray:
        return 1.0 - forest.predict_proba(z).max(axis=1)

    def _scaled(self, samples: np.ndarray) -> np.ndarray:
        return self.scaler_.transform(flatten(samples))

    # ---------------------------------------------------------------- fitting
    def _fit(self, dataset: TactileDataset, progress: bool) -> None:
        # The matrices here are small (about 200 features): multi-threaded BLAS only
        # adds overhead, and on a busy machine it is an order of magnitude slower.
        with threadpool_limits(limits=1, user_api="blas"):
            self._fit_all(dataset)

    def _fit_all(self, dataset: TactileDataset) -> None:
        present = np.unique(dataset.labels)
        if len(present) != dataset.n_classes:
            missing = sorted(set(range(dataset.n_classes)) - set(present.tolist()))
            raise DatasetError(f"every known class needs samples; none for {missing[:5]}")
        if dataset.n_classes < 2:
            raise DatasetError("a baseline needs at least 2 known classes")
        x = flatten(dataset.samples)
        y = dataset.labels

        # Sect. VI-B threshold tuning with a probe forest that never sees the validation data.
        fit_idx, known_idx, val_idx = novelty_validation_split(
            dataset,
            float(self.novelty_val_fraction),
            int(self.novelty_holdout_trials),
            seed=int(self.seed),
        )
        if len(known_idx) == 0 or len(val_idx) == 0:
            raise DatasetError("novelty tuning needs held-out trials and validation-novel objects")
        probe_scaler = RobustInputScaler().fit(x[fit_idx])
        probe = self._forest().fit(probe_scaler.transform(x[fit_idx]), y[fit_idx])
        self.novelty_tuning = tune_threshold(
            self._max_prob_score(probe, probe_scaler.transform(x[known_idx])),
            self._max_prob_score(probe, probe_scaler.transform(x[val_idx])),
        )
        self.novelty_threshold = float(self.novelty_tuning.threshold)

        self.scaler_ = RobustInputScaler().fit(x)
        z = self.scaler_.transform(x)
        self.forest_ = self._forest().fit(z, y)
        means = np.stack([z[y == c].mean(axis=0) for c in range(dataset.n_classes)])
        self.ncm_tau_ = float(np.median(np.linalg.norm(z - means[y], axis=1))) or 1.0
        if dataset.n_attributes:  # without attributes there is no zero-shot part to fit
            self._fit_zsl(z, dataset)
        self.novel_means_ = np.zeros((0, z.shape[1]), np.float32)
        self.novel_has_samples_ = np.zeros(0, bool)
        self.metrics = {
            "novelty_auroc_validation": self.novelty_tuning.auroc,
            "novelty_known_kept": self.novelty_tuning.known_kept_at_threshold,
            "novelty_val_novel": self.novelty_tuning.val_novel_at_threshold,
        }

    def _fit_zsl(self, z: np.ndarray, dataset: TactileDataset) -> None:
        """Train the zero-shot part on the scaled known-class samples."""
        raise NotImplementedError

    def _prepare_novel(self, attributes: np.ndarray) -> None:
        """Precompute what ``_zsl_proba`` needs for the novel classes' attribute vectors."""

    def _zsl_proba(self, z: np.ndarray) -> np.ndarray:
        """(N, L) zero-shot posterior over the registry's novel classes."""
        raise NotImplementedError

    # -------------------------------------------------------------- inference
    def _known_proba(self, samples: np.ndarray) -> np.ndarray:
        return self.forest_.predict_proba(self._scaled(samples))

    def _novelty_score(self, samples: np.ndarray) -> np.ndarray:
        return self._max_prob_score(self.forest_, self._scaled(samples))

    def _novel_proba(self, samples: np.ndarray) -> np.ndarray:
        return self._novel_from_scaled(self._scaled(samples))

    def _novel_from_scaled(self, z: np.ndarray) -> np.ndarray:
        p_zsl = self._zsl_proba(z)
        has = self.novel_has_samples_
        if not has.any():
            return p_zsl
        d = np.linalg.norm(z[:, None, :] - self.novel_means_[None, has, :], axis=2)
        p_ncm = softmax(-d / self.ncm_tau_)
        out = np.zeros_like(p_zsl)
        unsampled_mass = p_zsl[:, ~has].sum(axis=1, keepdims=True)
        out[:, has] = (1.0 - unsampled_mass) * p_ncm
        out[:, ~has] = p_zsl[:, ~has]
        return out

    def _all_scores(self, samples: np.ndarray):
        z = self._scaled(samples)
        known = self.forest_.predict_proba(z)
        novel = self._novel_from_scaled(z) if self.registry.novel_names else None
        return 1.0 - known.max(axis=1), known, novel

    # -------------------------------------------------------------- enrolment
    def _refit_novel(self, **options: Any) -> None:
        if options:
            raise FrameworkError(
                f"method '{self.method}' takes no enrolment options, got {sorted(options)}"
            )
        reg = self.registry
        self._prepare_novel(np.asarray(reg.novel_attributes, np.float32))
        d = self.novel_means_.shape[1]
        means = np.zeros((len(reg.novel_names), d), np.float32)
        has = np.zeros(len(reg.novel_names), bool)
        for i, name in enumerate(reg.novel_names):
            samples = reg.novel_samples.get(name)
            if samples is not None and len(samples):
                means[i] = self._scaled(samples).mean(axis=0)
                has[i] = True
        self.novel_means_, self.novel_has_samples_ = means, has

    # ------------------------------------------------------------ persistence
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        raise NotImplementedError(
            f"method '{self.method}' is evaluation-only: its extra-trees ensemble cannot be stored "
            "as plain arrays in a model bundle; use it through 'tactile-zsl evaluate'"
        )

    def set_state(self, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        raise NotImplementedError(
            f"method '{self.method}' is evaluation-only and has no model bundles to load"
        )


def validation_folds(
    dataset: TactileDataset, n_folds: int, val_fraction: float, seed: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(fit_classes, val_classes) pairs carved from the known classes for hyper-parameters.

    Validation objects follow the split rules (distinct vectors, covered by the fit
    objects); returns [] when the known set is too small to carve any.
    """
    k = dataset.n_classes
    n_val = max(2, int(round(val_fraction * k)))
    if n_val >= k - 1 or len(novel_candidates(dataset)) < n_val:
        return []
    rng = np.random.default_rng(seed)
    try:
        sets = draw_novel_sets(dataset, n_val, n_folds, rng, max_draws=5_000)
    except SplitError:
        return []
    return [(np.setdiff1d(np.arange(k), v), v) for v in sets]
