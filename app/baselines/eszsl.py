"""ESZSL: "An embarrassingly simple approach to zero-shot learning" (Romera-Paredes and
Torr, ICML 2015).

A bilinear compatibility x^T V s between a sample x (robust-scaled flat inputs,
d features) and a class signature s (its attribute vector, M entries), with the
closed form (X: n × d samples, Y: n × K in {−1, 1}, S: M × K known signatures)

    V = (X^T X + γ I)^{-1} X^T Y S^T (S S^T + λ I)^{-1}.

A novel class z scores x^T V a^z; ``novel_proba`` is the softmax of those scores
divided by the spread (standard deviation) of the known-class scores on the
training data. The signature normalisation (raw 0/1 vectors, centred on the
known classes' mean vector, unit length, or both; a common ZSL preprocessing),
γ and λ are picked from a grid by mean zero-shot accuracy on validation objects
carved from the known set (``validation_folds``: the split rules, several
folds), never on test data, then V is refitted on every known class. Known classes,
novelty and one-shot: extra-trees and nearest class mean, as in ``common``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.baselines.common import ForestBaseline, validation_folds
from app.data.dataset import TactileDataset
from app.framework.params import (
    Constraint,
    at_least,
    between,
    check,
    either,
    one_of,
    positive_values,
)
from app.methods.attributes import softmax

GAMMA_GRID = (1e-1, 1.0, 1e1, 1e2, 1e3, 1e4)
LAMBDA_GRID = (1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3)
SIGNATURE_MODES = ("raw", "centered", "l2", "centered_l2")


def eszsl_fit(
    x: np.ndarray, labels: np.ndarray, signatures: np.ndarray, gamma: float, lam: float
) -> np.ndarray:
    """V (d × M) from samples x (n × d), labels in [0, K) and signatures (K × M)."""
    return next(iter(eszsl_path(x, labels, signatures, (gamma,), (lam,)).values()))


def eszsl_path(
    x: np.ndarray,
    labels: np.ndarray,
    signatures: np.ndarray,
    gammas: Sequence[float],
    lambdas: Sequence[float],
) -> dict[tuple[float, float], np.ndarray]:
    """V for every (γ, λ) pair, sharing one eigendecomposition of X^T X and of S S^T."""
    x = np.asarray(x, np.float64)
    k = len(signatures)
    y = -np.ones((len(x), k))
    y[np.arange(len(x)), labels] = 1.0
    s = np.asarray(signatures, np.float64).T  # M × K
    f, w = np.linalg.eigh(s @ s.T)
    xys = x.T @ y @ s.T  # d × M
    if len(x) < x.shape[1]:
        # fewer samples than features: (X^T X + γI)^{-1} X^T = X^T (X X^T + γI)^{-1}
        e, q = np.linalg.eigh(x @ x.T)
        qys = q.T @ (y @ s.T)  # n × M
        xq = x.T @ q  # d × n
    else:
        e, u = np.linalg.eigh(x.T @ x)
        ub = u.T @ xys
    e = np.maximum(e, 0.0)
    out = {}
    for g in gammas:
        left = xq @ (qys / (e + g)[:, None]) if len(x) < x.shape[1] else u @ (ub / (e + g)[:, None])
        lw = left @ w  # (X^T X + γI)^{-1} X^T Y S^T in S S^T's eigenbasis
        for lam in lambdas:
            out[(g, lam)] = (lw / (np.maximum(f, 0.0) + lam)[None, :]) @ w.T
    return out


def signatures(attributes: np.ndarray, mode: str, known_mean: np.ndarray) -> np.ndarray:
    """Class signatures from 0/1 attribute vectors: ``raw``, ``centered`` (minus the known
    classes' mean vector), ``l2`` (unit length) or ``centered_l2``."""
    s = np.asarray(attributes, np.float64)
    if mode in ("centered", "centered_l2"):
        s = s - known_mean
    if mode in ("l2", "centered_l2"):
        s = s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)
    return s


class ESZSLRecognizer(ForestBaseline):
    """ESZSL zero-shot on robust-scaled inputs; known classes and novelty by extra-trees.

    Parameters
    ----------
    gamma : float or None, default None
        γ, the ridge on the samples' side, (X^T X + γ I)^{-1}. None: chosen from
        ``gammas`` on validation objects. Positive or None.
    lam : float or None, default None
        λ, the ridge on the signatures' side, (S S^T + λ I)^{-1}. None: chosen from
        ``lambdas`` on validation objects. Positive or None.
    signature : {"raw", "centered", "l2", "centered_l2"} or None, default None
        How a class's 0/1 attribute vector becomes its signature: as it is, minus the
        known classes' mean vector, scaled to unit length, or both. None: chosen from
        ``signature_modes`` on validation objects.
    gammas : sequence of float, default ``GAMMA_GRID``
        The candidates for γ when ``gamma`` is None. Positive values.
    lambdas : sequence of float, default ``LAMBDA_GRID``
        The candidates for λ when ``lam`` is None. Positive values.
    signature_modes : sequence of str, default ``SIGNATURE_MODES``
        The candidates for the signature when ``signature`` is None.
    val_folds : int, default 5
        Sets of validation objects, carved from the known set, over which every
        candidate's mean zero-shot accuracy is measured. At least 1.
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

    method = "eszsl"

    _parameter_constraints = {
        **ForestBaseline._parameter_constraints,
        **{
            name: either(
                one_of((None,)),
                Constraint(lambda v: v > 0, "be positive"),
                must="be positive or None (chosen on validation)",
            )
            for name in ("gamma", "lam")
        },
        "gammas": positive_values(),
        "lambdas": positive_values(),
        "val_folds": at_least(1),
        "val_fraction": between(0, 1),
    }

    def __init__(
        self,
        gamma: float | None = None,
        lam: float | None = None,
        signature: str | None = None,
        gammas: Sequence[float] = GAMMA_GRID,
        lambdas: Sequence[float] = LAMBDA_GRID,
        signature_modes: Sequence[str] = SIGNATURE_MODES,
        val_folds: int = 5,
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
        self.gamma = gamma
        self.lam = lam
        self.signature = signature
        self.gammas = gammas
        self.lambdas = lambdas
        self.signature_modes = signature_modes
        self.val_folds = val_folds
        self.val_fraction = val_fraction

    def _modes(self) -> tuple[str, ...]:
        """The signatures to choose from: ``signature`` alone when given."""
        return (self.signature,) if self.signature is not None else tuple(self.signature_modes)

    def _validate_params(self) -> None:
        super()._validate_params()
        modes = self._modes()
        check(
            len(modes) > 0 and all(m in SIGNATURE_MODES for m in modes),
            f"signature modes must be among {SIGNATURE_MODES}, got {modes}",
        )

    def _choose(self, z: np.ndarray, dataset: TactileDataset) -> tuple[str, float, float, dict]:
        gammas = (self.gamma,) if self.gamma is not None else tuple(float(g) for g in self.gammas)
        lambdas = (self.lam,) if self.lam is not None else tuple(float(v) for v in self.lambdas)
        modes = self._modes()
        if len(gammas) == 1 and len(lambdas) == 1 and len(modes) == 1:
            return modes[0], gammas[0], lambdas[0], {}
        folds = validation_folds(
            dataset, int(self.val_folds), float(self.val_fraction), int(self.seed)
        )
        if not folds:  # too few known objects to carve validation objects: middle of the grid
            return modes[0], gammas[len(gammas) // 2], lambdas[len(lambdas) // 2], {}
        attrs, y = dataset.class_attributes, dataset.labels
        acc = np.zeros((len(modes), len(gammas), len(lambdas)))
        for fit_c, val_c in folds:
            fit, val = np.isin(y, fit_c), np.isin(y, val_c)
            remap = np.full(dataset.n_classes, -1)
            remap[fit_c] = np.arange(len(fit_c))
            truth = np.searchsorted(val_c, y[val])
            for k, mode in enumerate(modes):
                sig = signatures(attrs, mode, attrs[fit_c].mean(axis=0))
                path = eszsl_path(z[fit], remap[y[fit]], sig[fit_c], gammas, lambdas)
                for i, g in enumerate(gammas):
                    for j, lam in enumerate(lambdas):
                        pred = (z[val] @ path[(g, lam)] @ sig[val_c].T).argmax(axis=1)
                        acc[k, i, j] += np.mean(pred == truth) / len(folds)
        # ties go to the later grid entries (the strongest regularisation)
        k, i, j = np.unravel_index(np.flatnonzero(acc == acc.max())[-1], acc.shape)
        grid = {
            f"signature={mode},gamma={g:g},lambda={lam:g}": float(acc[c, a, b])
            for c, mode in enumerate(modes)
            for a, g in enumerate(gammas)
            for b, lam in enumerate(lambdas)
        }
        return modes[k], gammas[i], lambdas[j], grid

    def _fit_zsl(self, z: np.ndarray, dataset: TactileDataset) -> None:
        mode, gamma, lam, grid = self._choose(z, dataset)
        self.signature_, self.gamma_, self.lambda_ = mode, float(gamma), float(lam)
        self.known_mean_ = dataset.class_attributes.mean(axis=0).astype(np.float64)
        sig = signatures(dataset.class_attributes, mode, self.known_mean_)
        self.V_ = eszsl_fit(z, dataset.labels, sig, gamma, lam)
        scores = z @ self.V_ @ sig.T
        self.score_scale_ = float(scores.std()) or 1.0
        self.zsl_validation_ = grid

    def _prepare_novel(self, attributes: np.ndarray) -> None:
        self.novel_signatures_ = signatures(attributes, self.signature_, self.known_mean_)

    def _zsl_proba(self, z: np.ndarray) -> np.ndarray:
        scores = z.astype(np.float64) @ self.V_ @ self.novel_signatures_.T
        return softmax(scores / self.score_scale_)
