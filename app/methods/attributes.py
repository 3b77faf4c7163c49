"""Per-attribute logistic classifiers stored as arrays, and Direct Attribute Prediction.

DAP (Lampert et al.): a novel class z with attribute vector a^z scores

    log p(z | x) = sum_m log p(a_m = a^z_m | x) - log p(a_m = a^z_m) + const,

with p(a_m | x) from one L2-regularised logistic regression per attribute,
clipped to [clip, 1 - clip] so that one confident classifier cannot veto a class
alone, and the prior p(a_m = 1) the mean of the known classes' vectors.

Attribute values may be graded (0.5: "somewhat soft") or not known (NaN). A graded value
a is a soft target: the class's term is a log p + (1 - a) log(1 - p), and the attribute's
classifier learns from each sample twice, as present with weight a and as absent with
weight 1 - a (the cross-entropy against a soft label). A value not known leaves the
attribute out: out of that class's product (p(a_m) / p(a_m) marginalised to 1), out of the
classifier's training samples, out of the prior's mean. Vectors of only 0 and 1 give the
same numbers as before graded values existed.
"""

from __future__ import annotations

import numpy as np

from app.framework.attribute_values import attribute_prior, impute

__all__ = ["attribute_prior", "impute"]  # re-exported: the methods read them from here
#: above this many features, and more features than samples, the autoencoder is solved in
#: the samples' span (``semantic_autoencoder``); up to it the D x D Schur form takes a second
_SAE_DIRECT = 1024


# The DAP baseline (app/baselines/dap.py) scores with these too: one DAP rule for both.
def dap_log_scores(
    attr_proba: np.ndarray, class_attributes: np.ndarray, prior: np.ndarray, clip: float
) -> np.ndarray:
    """(N, L) log ∏_m p(a_m = a^z_m | x) / p(a_m = a^z_m) for L class vectors (graded
    values as soft targets, values not known left out)."""
    p = np.clip(attr_proba, clip, 1 - clip)
    q = np.clip(prior, clip, 1 - clip)
    present, absent = dap_class_terms(class_attributes)
    log_like = np.log(p) @ present.T + np.log1p(-p) @ absent.T
    log_prior = np.log(q) @ present.T + np.log1p(-q) @ absent.T
    return log_like - log_prior[None, :]


def dap_class_terms(class_attributes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(L, M) weights of log p and of log(1 - p) in each class's DAP product: a and 1 - a,
    0 and 0 where the value is not known (NaN)."""
    a = np.asarray(class_attributes, np.float64)
    known = ~np.isnan(a)
    return np.where(known, a, 0.0), np.where(known, 1.0 - a, 0.0)


def softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


class LinearAttributeModel:
    """p(a_m = 1 | z) = sigmoid(z · w_m + b_m); an attribute constant over the known
    classes keeps that constant (w_m = 0, b_m = ±inf stands for probability 1 or 0)."""

    def __init__(self, weights: np.ndarray, bias: np.ndarray, constant: np.ndarray) -> None:
        self.weights = np.asarray(weights, np.float64)  # (M, D)
        self.bias = np.asarray(bias, np.float64)  # (M,)
        self.constant = np.asarray(constant, np.float64)  # (M,), NaN where the attribute varies
        m = len(self.bias)
        if self.weights.ndim != 2 or self.weights.shape[0] != m or self.constant.shape != (m,):
            raise ValueError("attribute model arrays are inconsistent")
        # Recognition multiplies in float32, as the scaled inputs come: converting a batch
        # to float64 cost more than the product, and logits need no more precision.
        self._weights_t32 = np.ascontiguousarray(self.weights.T, np.float32)

    @property
    def weights_t32(self) -> np.ndarray:
        """(D, M) float32 C-ordered weights, the matrix ``predict_proba`` multiplies by."""
        return self._weights_t32

    def __deepcopy__(self, memo: dict) -> LinearAttributeModel:
        return self  # never changed after its fit: models derived by enrolment share it

    @classmethod
    def fit(
        cls,
        z: np.ndarray,
        targets: np.ndarray,
        C: float,
        max_iter: int = 1000,
        n_jobs: int | None = 1,
    ) -> LinearAttributeModel:
        """One classifier per column of ``targets`` (N, M): each sample's class's values in
        [0, 1], NaN where not known. An attribute learns from the samples whose value is
        known; with no such sample, or one value for all of them, it is that constant (0.5
        where nothing is known). ``n_jobs`` classifiers are fitted at once, in threads
        (joblib's; -1: every core): the same classifiers, sooner."""
        from joblib import Parallel, delayed  # fitting only, as fit_one's scikit-learn

        m = targets.shape[1]
        weights = np.zeros((m, z.shape[1]))
        bias = np.zeros(m)
        constant = np.full(m, np.nan)
        # threads, not processes: the products inside release the GIL, and z is not copied
        every = Parallel(n_jobs=n_jobs, prefer="threads")(
            delayed(cls.fit_one)(z, targets[:, j], C, max_iter) for j in range(m)
        )
        for j, fitted in enumerate(every):
            if isinstance(fitted, float):
                constant[j] = fitted
            else:
                weights[j], bias[j] = fitted
        return cls(weights, bias, constant)

    @staticmethod
    def fit_one(
        z: np.ndarray, target: np.ndarray, C: float, max_iter: int = 1000
    ) -> float | tuple[np.ndarray, float]:
        """The constant probability of one attribute, or its classifier's (weights, bias)."""
        from sklearn.linear_model import LogisticRegression  # fitting only: loading stays light

        target = np.asarray(target, np.float64)
        known = ~np.isnan(target)
        values = np.unique(target[known])
        if len(values) == 0:
            return 0.5
        if len(values) == 1:
            return float(values[0])
        lr = LogisticRegression(C=C, max_iter=max_iter)
        if np.isin(values, (0.0, 1.0)).all():
            lr.fit(z[known], target[known].astype(np.int64))
        else:  # a soft label: each sample present with weight a and absent with 1 - a
            x, a = z[known], target[known]
            lr.fit(
                np.concatenate([x, x]),
                np.r_[np.ones(len(a), np.int64), np.zeros(len(a), np.int64)],
                sample_weight=np.r_[a, 1.0 - a],
            )
        return lr.coef_[0], float(lr.intercept_[0])

    def predict_proba(self, z: np.ndarray) -> np.ndarray:
        """(N, M) probabilities that each attribute is present."""
        logits = (np.asarray(z, np.float32) @ self._weights_t32).astype(np.float64) + self.bias
        p = 0.5 * (1.0 + np.tanh(0.5 * logits))  # a sigmoid that cannot overflow
        fixed = ~np.isnan(self.constant)
        p[:, fixed] = self.constant[fixed]
        return p

    def get_state(self) -> dict[str, np.ndarray]:
        return {"weights": self.weights, "bias": self.bias, "constant": self.constant}

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray]) -> LinearAttributeModel:
        return cls(arrays["weights"], arrays["bias"], arrays["constant"])


def semantic_autoencoder(z: np.ndarray, targets: np.ndarray, lam: float) -> np.ndarray:
    """The semantic autoencoder of Kodirov et al. (2017): the (M, D) projection W that
    minimises ||Z - W^T A||^2 + lam ||W Z - A||^2 over samples Z (D, N) and their classes'
    attribute vectors A (M, N), in closed form by the Sylvester equation
    (A A^T) W + W (lam Z Z^T) = (1 + lam) A Z^T. A tiny ridge on A A^T keeps the equation
    solvable when an attribute is constant over the known classes."""
    from scipy.linalg import solve_sylvester

    x = np.asarray(z, np.float64).T
    a = np.asarray(targets, np.float64).T
    aa = a @ a.T
    aa += 1e-6 * max(float(np.trace(aa)) / len(aa), 1.0) * np.eye(len(aa))
    if x.shape[0] > max(x.shape[1], _SAE_DIRECT):
        # more features than samples: with X = U S V^T (thin), W = W' U^T solves it exactly
        # where (A A^T) W' + W' (lam S^2) = (1 + lam) A V S, one M x M system per column; the
        # Schur form of the D x D equation took minutes and gigabytes at 10,000 features
        u, s, vt = np.linalg.svd(x, full_matrices=False)
        rhs = (1.0 + lam) * (a @ vt.T) * s
        w = np.stack(
            [
                np.linalg.solve(aa + lam * si**2 * np.eye(len(aa)), rhs[:, i])
                for i, si in enumerate(s)
            ],
            axis=1,
        )
        return w @ u.T
    return solve_sylvester(aa, lam * (x @ x.T), (1.0 + lam) * (a @ x.T))


def cosine_scores(z: np.ndarray, projection: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(N, L) cosine between each projected sample W z and each class's attribute vector."""

    def unit(m: np.ndarray) -> np.ndarray:
        return m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)

    projected = np.asarray(z, np.float32) @ np.asarray(projection, np.float32).T
    return unit(projected.astype(np.float64)) @ unit(np.asarray(vectors, np.float64)).T


def fit_zero_shot(
    z: np.ndarray,
    y: np.ndarray,
    class_attributes: np.ndarray,
    C: float,
    max_samples: int,
    sae_lambda: float,
    seed: int,
    n_jobs: int | None,
) -> tuple[LinearAttributeModel, np.ndarray, np.ndarray | None]:
    """(attribute classifiers, prior, autoencoder or None) learnt from inputs ``z`` of known
    classes ``y`` whose vectors are ``class_attributes`` (K, M): DAP's classifiers on at
    most ``max_samples`` samples (a random share of every class, seeded; 0: all), the prior,
    and the semantic autoencoder where ``sae_lambda`` > 0 and there are attributes."""
    if 0 < max_samples < len(z):
        rng = np.random.default_rng(int(seed))
        keep = np.sort(rng.choice(len(z), int(max_samples), replace=False))
        z, y = z[keep], y[keep]
    attributes = LinearAttributeModel.fit(z, class_attributes[y], float(C), n_jobs=n_jobs)
    prior = attribute_prior(class_attributes)
    sae = None
    if sae_lambda > 0 and class_attributes.shape[1] > 0:
        targets = impute(class_attributes, prior)[y]
        sae = semantic_autoencoder(z, targets, float(sae_lambda)).astype(np.float32)
    return attributes, prior, sae


def zero_shot_proba(
    z: np.ndarray,
    attributes: LinearAttributeModel,
    prior: np.ndarray,
    sae: np.ndarray | None,
    novel_attributes: np.ndarray,
    clip: float,
    sae_temperature: float,
) -> np.ndarray:
    """(N, L) zero-shot posterior over L described classes: DAP's log scores plus
    ``sae_temperature`` x the autoencoder's cosines, a softmax."""
    scores = dap_log_scores(attributes.predict_proba(z), novel_attributes, prior, float(clip))
    if sae is not None:
        scores = scores + float(sae_temperature) * cosine_scores(
            z, sae, impute(novel_attributes, prior)
        )
    return softmax(scores)
