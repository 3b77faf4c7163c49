"""Per-attribute logistic classifiers stored as arrays, and Direct Attribute Prediction.

DAP (Lampert et al.): a novel class z with attribute vector a^z scores

    log p(z | x) = sum_m log p(a_m = a^z_m | x) - log p(a_m = a^z_m) + const,

with p(a_m | x) from one L2-regularised logistic regression per attribute,
clipped to [clip, 1 - clip] so that one confident classifier cannot veto a class
alone, and the prior p(a_m = 1) the mean of the known classes' vectors.
"""

from __future__ import annotations

import numpy as np


# The DAP baseline (app/baselines/dap.py) scores with these too: one DAP rule for both.
def dap_log_scores(
    attr_proba: np.ndarray, class_attributes: np.ndarray, prior: np.ndarray, clip: float
) -> np.ndarray:
    """(N, L) log ∏_m p(a_m = a^z_m | x) / p(a_m = a^z_m) for L class vectors."""
    p = np.clip(attr_proba, clip, 1 - clip)
    q = np.clip(prior, clip, 1 - clip)
    a = (np.asarray(class_attributes) > 0.5).astype(np.float64)
    log_like = np.log(p) @ a.T + np.log1p(-p) @ (1 - a).T
    log_prior = np.log(q) @ a.T + np.log1p(-q) @ (1 - a).T
    return log_like - log_prior[None, :]


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

    @classmethod
    def fit(
        cls, z: np.ndarray, targets: np.ndarray, C: float, max_iter: int = 1000
    ) -> LinearAttributeModel:
        from sklearn.linear_model import LogisticRegression  # fitting only: loading stays light

        targets = (np.asarray(targets) > 0.5).astype(np.int64)
        m = targets.shape[1]
        weights = np.zeros((m, z.shape[1]))
        bias = np.zeros(m)
        constant = np.full(m, np.nan)
        for j in range(m):
            values = np.unique(targets[:, j])
            if len(values) == 1:
                constant[j] = float(values[0])
                continue
            lr = LogisticRegression(C=C, max_iter=max_iter).fit(z, targets[:, j])
            weights[j], bias[j] = lr.coef_[0], lr.intercept_[0]
        return cls(weights, bias, constant)

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
    return solve_sylvester(aa, lam * (x @ x.T), (1.0 + lam) * (a @ x.T))


def cosine_scores(z: np.ndarray, projection: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(N, L) cosine between each projected sample W z and each class's attribute vector."""

    def unit(m: np.ndarray) -> np.ndarray:
        return m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)

    projected = np.asarray(z, np.float32) @ np.asarray(projection, np.float32).T
    return unit(projected.astype(np.float64)) @ unit(np.asarray(vectors, np.float64)).T
