"""Direct Attribute Prediction (DAP; Lampert, Nickisch and Harmeling, CVPR 2009 / TPAMI 2014).

One probabilistic classifier per attribute is trained on the known objects'
samples, each sample labelled with its object's attribute value. A novel class z
with attribute vector a^z scores

    p(z | x) ∝ ∏_m p(a_m = a^z_m | x) / p(a_m = a^z_m),

with the attribute prior p(a_m = 1) the mean of the known classes' vectors (as in
DAP), computed in log space and normalised over the novel classes. Attribute
probabilities are clipped to [clip, 1 − clip] so one confident classifier cannot
veto a class alone; an attribute constant over the known classes gets that
constant probability (clipped).

Attribute classifiers: L2-regularised logistic regression (``"logistic"``, the
``dap`` method; its C is chosen on validation objects carved from the known set
when ``C="auto"``), or one multi-output extra-trees forest (``"extratrees"``,
used by the ``extratrees`` method). Known classes and novelty: see ``common``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit
from sklearn.ensemble import ExtraTreesClassifier

from app.baselines.common import ForestBaseline, validation_folds
from app.data.dataset import TactileDataset
from app.framework.params import at_least, between, either, number, one_of
from app.methods.attributes import dap_log_scores, softmax

ATTRIBUTE_MODELS = ("logistic", "extratrees")
C_GRID = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0)


class AttributePredictor:
    """p(a_m = 1 | z) for every attribute m, from scaled flat inputs z."""

    def __init__(
        self, model: str, C: float, n_estimators: int, seed: int, n_jobs: int | None
    ) -> None:
        self.model = model
        self.C = C
        self.n_estimators = n_estimators
        self.seed = seed
        self.n_jobs = n_jobs

    def fit(
        self, z: np.ndarray, targets: np.ndarray, warm: AttributePredictor | None = None
    ) -> AttributePredictor:
        """``warm``: a logistic predictor fitted on the same data with another C, to start from."""
        targets = (np.asarray(targets) > 0.5).astype(np.int64)
        m = targets.shape[1]
        self.constant_ = np.full(m, np.nan)
        varying = []
        for j in range(m):
            values = np.unique(targets[:, j])
            if len(values) == 1:
                self.constant_[j] = float(values[0])
            else:
                varying.append(j)
        self.varying_ = np.asarray(varying, dtype=np.int64)
        self.models_: list = []
        if not len(varying):
            return self
        if self.model == "extratrees":
            forest = ExtraTreesClassifier(
                n_estimators=self.n_estimators, random_state=self.seed, n_jobs=self.n_jobs
            )
            self.models_ = [forest.fit(z, targets[:, self.varying_])]
        else:
            init = None
            if warm is not None and warm.models_ and np.array_equal(warm.varying_, self.varying_):
                init = warm.models_[0]
            self.models_ = [fit_logistic(z, targets[:, self.varying_], self.C, init=init)]
        return self

    def predict_proba(self, z: np.ndarray) -> np.ndarray:
        """(N, M) probabilities that each attribute is present."""
        out = np.tile(self.constant_, (len(z), 1))
        if not len(self.varying_):
            return out
        if self.model == "extratrees":
            per_output = self.models_[0].predict_proba(z)
            if len(self.varying_) == 1:
                per_output = [per_output]
            cols = [p[:, 1] for p in per_output]  # classes_ are [0, 1] for varying outputs
        else:
            w, b = self.models_[0]
            out[:, self.varying_] = expit(np.asarray(z, np.float64) @ w + b)
            return out
        out[:, self.varying_] = np.stack(cols, axis=1)
        return out


def fit_logistic(
    x: np.ndarray,
    targets: np.ndarray,
    C: float,
    max_iter: int = 500,
    init: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Independent L2-regularised logistic regressions, one per target column, fitted
    jointly by L-BFGS: minimises C · Σ log-loss + ½‖w_m‖² per column (scikit-learn's
    objective; intercepts unpenalised). Returns weights (d × M) and intercepts (M,);
    ``init`` (weights, intercepts) warm-starts the solver."""
    x = np.asarray(x, np.float64)
    t = np.asarray(targets, np.float64)
    n, d = x.shape
    m = t.shape[1]

    def loss_grad(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w, b = theta[: d * m].reshape(d, m), theta[d * m :]
        logits = x @ w + b
        # log(1 + e^l) - t·l, stably
        loss = C * float(np.sum(np.logaddexp(0.0, logits) - t * logits)) + 0.5 * float(
            np.sum(w * w)
        )
        r = C * (expit(logits) - t)
        return loss, np.concatenate([(x.T @ r + w).ravel(), r.sum(axis=0)])

    theta0 = np.zeros(d * m + m) if init is None else np.concatenate([np.ravel(init[0]), init[1]])
    res = minimize(loss_grad, theta0, jac=True, method="L-BFGS-B", options={"maxiter": max_iter})
    return res.x[: d * m].reshape(d, m), res.x[d * m :]


class DAPRecognizer(ForestBaseline):
    """DAP zero-shot on robust-scaled inputs; known classes and novelty by extra-trees.

    Parameters
    ----------
    attribute_model : {"logistic", "extratrees"}, default "logistic"
        The attribute classifiers p(a_m | x): one L2-regularised logistic regression
        per attribute, or one multi-output extra-trees forest for all of them.
    C : float or "auto", default "auto"
        Inverse strength of the logistic regressions' L2 penalty; "auto" chooses it
        from ``C_GRID`` by the mean zero-shot accuracy on validation objects carved
        from the known set. Positive or "auto"; unused by "extratrees".
    attribute_estimators : int, default 300
        Trees of the multi-output attribute forest ("extratrees" only).
    clip : float, default 0.02
        Attribute probabilities, and the attribute prior, are clipped to
        [clip, 1 - clip], so that no single attribute classifier can veto a novel
        class alone. In (0, 0.5).
    val_folds : int, default 3
        Sets of validation objects over which "auto" measures each C. At least 1.
    val_fraction : float, default 0.1
        Share of the known objects in each set of validation objects (at least 2).
        In (0, 1).
    n_estimators, max_features, min_samples_leaf, novelty_val_fraction,
    novelty_holdout_trials, seed, n_jobs
        The known-class forest and the novelty tuning, with ``ForestBaseline``'s
        meanings and defaults.
    featurizer_params
        The raw-trial featurizer's options, as ``ForestBaseline`` takes them.
    """

    method = "dap"

    _parameter_constraints = {
        **ForestBaseline._parameter_constraints,
        "attribute_model": one_of(ATTRIBUTE_MODELS),
        "C": either(one_of(("auto",)), number(0), must="be positive or 'auto'"),
        "clip": between(0, 0.5),
        "val_folds": at_least(1),
        "val_fraction": between(0, 1),
    }

    def __init__(
        self,
        attribute_model: str = "logistic",
        C: float | str = "auto",
        attribute_estimators: int = 300,
        clip: float = 0.02,
        val_folds: int = 3,
        val_fraction: float = 0.1,
        n_estimators: int = 300,
        max_features: str | float = "sqrt",
        min_samples_leaf: int = 1,
        novelty_val_fraction: float = 0.1,
        novelty_holdout_trials: int = 1,
        seed: int = 0,
        n_jobs: int | None = -1,
        featurizer_params: dict | None = None,
    ) -> None:
        super().__init__(
            n_estimators=n_estimators,
            max_features=max_features,
            min_samples_leaf=min_samples_leaf,
            novelty_val_fraction=novelty_val_fraction,
            novelty_holdout_trials=novelty_holdout_trials,
            seed=seed,
            n_jobs=n_jobs,
            featurizer_params=featurizer_params,
        )
        self.attribute_model = attribute_model
        self.C = C
        self.attribute_estimators = attribute_estimators
        self.clip = clip
        self.val_folds = val_folds
        self.val_fraction = val_fraction

    def _predictor(self, C: float) -> AttributePredictor:
        return AttributePredictor(
            self.attribute_model, C, int(self.attribute_estimators), int(self.seed), self.n_jobs
        )

    def _choose_C(self, z: np.ndarray, dataset: TactileDataset) -> tuple[float, dict]:
        """C with the best mean ZSL accuracy on validation objects carved from the known set."""
        folds = validation_folds(
            dataset, int(self.val_folds), float(self.val_fraction), int(self.seed)
        )
        if not folds:
            return 0.1, {}
        attrs, y = dataset.class_attributes, dataset.labels
        accs: dict[float, list[float]] = {C: [] for C in C_GRID}
        for fit_c, val_c in folds:
            fit, val = np.isin(y, fit_c), np.isin(y, val_c)
            truth = np.searchsorted(val_c, y[val])  # val_c is sorted
            previous = None
            for C in sorted(C_GRID):  # along the regularisation path, warm-started
                previous = self._predictor(C).fit(z[fit], attrs[y[fit]], warm=previous)
                s = dap_log_scores(
                    previous.predict_proba(z[val]),
                    attrs[val_c],
                    attrs[fit_c].mean(axis=0),
                    float(self.clip),
                )
                accs[C].append(float(np.mean(s.argmax(axis=1) == truth)))
        scores = {C: float(np.mean(a)) for C, a in accs.items()}
        best = max(scores, key=lambda c: (scores[c], -abs(np.log10(c) + 1)))
        return best, scores

    def _fit_zsl(self, z: np.ndarray, dataset: TactileDataset) -> None:
        attrs = dataset.class_attributes
        C, grid = self.C, {}
        if self.attribute_model == "logistic" and C == "auto":
            C, grid = self._choose_C(z, dataset)
        self.C_ = float(C) if C != "auto" else float("nan")
        self.attributes_ = self._predictor(self.C_).fit(z, attrs[dataset.labels])
        self.attribute_prior_ = attrs.mean(axis=0).astype(np.float64)
        self.zsl_validation_ = {str(k): v for k, v in grid.items()}

    def _prepare_novel(self, attributes: np.ndarray) -> None:
        self.novel_vectors_ = attributes

    def _zsl_proba(self, z: np.ndarray) -> np.ndarray:
        p = self.attributes_.predict_proba(z)
        return softmax(
            dap_log_scores(p, self.novel_vectors_, self.attribute_prior_, float(self.clip))
        )
