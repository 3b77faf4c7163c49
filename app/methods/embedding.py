"""The ``prototypes`` method's representation: a discriminant space and prototypes in it.

- ``SubclassEmbedding``: the scaled inputs are whitened by their within-class covariance
  (Ledoit-Wolf shrinkage of the correlations, as scikit-learn's shrinkage LDA), then rotated
  so that the directions along which the prototypes differ most come first. A class whose
  trials gather in several clusters (contact modes: grasp poses, contact locations) is
  split into *subclasses* by 2-means (in that space at a strong shrinkage), recursively,
  while a split leaves at most ``split_ratio`` of the class's spread; the covariance is
  then estimated again within the subclasses, so a class's modes no longer count as noise.
  Where no class splits this is shrinkage LDA's space, full rank; where classes split it is
  subclass discriminant analysis.
- The prototypes (``app.methods.prototypes``) are the subclasses' means in that space,
  searched by ``app.methods.prototype_search``.
"""

from __future__ import annotations

import copy

import numpy as np

from app.methods.known import class_means

_ROWS = 8192  # rows a blocked pass over the samples takes at a time
#: rows of within-subclass residuals from which Ledoit-Wolf's shrinkage is estimated
_SHRINKAGE_ROWS = 20_000
#: classes are split where their trials are whitened at this shrinkage: nearly each feature's
#: own spread, so a class's modes are not whitened away as the fit's noise (on the simulator
#: with 3 modes, 8 trials a class, the best split keeps a median 0.49 of a class's spread
#: here, 0.72 at Ledoit-Wolf's 0.08; one Gaussian cluster keeps 0.84)
_SPLIT_SHRINKAGE = 0.9


class SubclassEmbedding:
    """Whitening by the shrunk within-subclass covariance, rotated (module docstring).

    Parameters
    ----------
    max_modes : int
        the most subclasses a class is split into (1: never split, shrinkage LDA).
    split_ratio : float in (0, 1)
        a split is kept where the two halves' summed squared spread is at most this share
        of the whole's, measured at the shrinkage ``_SPLIT_SHRINKAGE``. For one Gaussian
        cluster of n samples in many dimensions the best split leaves about (n - 2) / (n - 1)
        of it (6/7 for 8 samples).
    min_mode_samples : int
        the fewest samples a subclass keeps.
    seed : int
        seeds the rows Ledoit-Wolf's shrinkage is estimated from.
    """

    def __init__(
        self, max_modes: int = 3, split_ratio: float = 0.7, min_mode_samples: int = 1, seed: int = 0
    ) -> None:
        self.max_modes = max_modes
        self.split_ratio = split_ratio
        self.min_mode_samples = min_mode_samples
        self.seed = seed

    def fit(self, z: np.ndarray, y: np.ndarray, n_classes: int) -> SubclassEmbedding:
        """Learn the space from scaled inputs ``z`` (N, D) of classes ``y`` (N,); sets
        ``subclass_`` (N,), each sample's subclass, ``subclass_class_`` (S,), and
        ``subclass_means_`` (S, D), the subclasses' means in the inputs' space (until
        ``release``)."""
        z = np.asarray(z, np.float32)
        y = np.asarray(y, np.int64)
        sub, owner = y, np.arange(n_classes)
        self._whiten(z, sub, len(owner))
        if self.max_modes > 1:
            sub, owner = self._modes(self.shrunk(_SPLIT_SHRINKAGE).transform(z), y, n_classes)
            self._whiten(z, sub, len(owner))
        self.subclass_, self.subclass_class_ = sub, owner
        return self

    def release(self) -> SubclassEmbedding:
        """Drop what only the fit needs (its correlations and subclass means)."""
        for name in ("_corr", "_std", "subclass_means_", "_between"):
            self.__dict__.pop(name, None)
        return self

    def transform(self, z: np.ndarray) -> np.ndarray:
        """(N, D) float32 coordinates of scaled inputs in the space."""
        out = np.empty((len(z), self.projection_.shape[1]), np.float32)
        for lo in range(0, len(z), _ROWS):
            rows = np.asarray(z[lo : lo + _ROWS], np.float32)
            out[lo : lo + len(rows)] = (rows - self.center_) @ self.projection_
        return out

    def marginal(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(centre, projection) of the same Gaussian model restricted to ``features`` (the
        scaled inputs' columns a sample holds): whitening by the covariance's block there,
        whose coordinates give the distances the full model's marginal gives."""
        cov = self.covariance_[np.ix_(features, features)]
        vals, vecs = np.linalg.eigh(cov)
        # a block of constant features has no variance at all: floor it as a tiny one
        proj = vecs / np.sqrt(np.maximum(vals, max(1e-12 * vals.max(), 1e-12)))
        return self.center_[features], proj.astype(np.float32)

    def get_state(self) -> dict[str, np.ndarray]:
        return {
            "center": self.center_,
            "projection": self.projection_,
            "covariance": self.covariance_,
            "shrinkage": np.asarray(self.shrinkage_),
        }

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray]) -> SubclassEmbedding:
        new = cls()
        new.center_ = np.asarray(arrays["center"], np.float32)
        new.projection_ = np.asarray(arrays["projection"], np.float32)
        new.covariance_ = np.asarray(arrays["covariance"], np.float32)
        new.shrinkage_ = float(arrays["shrinkage"])
        return new

    # ------------------------------------------------------------------ fitting
    def _whiten(self, z: np.ndarray, sub: np.ndarray, n_sub: int) -> None:
        """The within-subclass correlations and spreads, then the space at Ledoit-Wolf's
        shrinkage of them (``shrunk`` moves it)."""
        from sklearn.covariance import ledoit_wolf_shrinkage

        means = class_means(z, sub, n_sub)
        d = z.shape[1]
        scatter = np.zeros((d, d))
        for lo in range(0, len(z), _ROWS):
            r = z[lo : lo + _ROWS] - means[sub[lo : lo + _ROWS]]
            scatter += r.T.astype(np.float64) @ r
        cov = scatter / max(len(z) - n_sub, 1)
        std = np.sqrt(np.maximum(np.diag(cov), 1e-12))
        rng = np.random.default_rng(self.seed)
        rows = rng.choice(len(z), min(len(z), _SHRINKAGE_ROWS), replace=False)
        resid = (z[rows] - means[sub[rows]]) / std
        self.ledoit_wolf_ = float(ledoit_wolf_shrinkage(resid, assume_centered=True))
        spread = means - means.mean(axis=0)
        self._corr, self._std, self.subclass_means_ = cov / np.outer(std, std), std, means
        self._between = spread.T @ spread  # (D, D): the prototypes' scatter, once
        self._project(self.ledoit_wolf_)

    def shrunk(self, shrinkage: float) -> SubclassEmbedding:
        """The same fit at another shrinkage of the within-subclass correlations (in [0, 1])."""
        new = copy.copy(self)
        new._project(float(shrinkage))
        return new

    def _project(self, shrink: float) -> None:
        d = len(self._std)
        corr = (1.0 - shrink) * self._corr + shrink * np.eye(d)
        vals, vecs = np.linalg.eigh(corr)
        white = (vecs / np.sqrt(np.maximum(vals, 1e-12))) / self._std[:, None]
        center = self.subclass_means_.mean(axis=0)
        # rotate: the prototypes' own principal directions first (distances unchanged)
        _, vecs = np.linalg.eigh(white.T @ self._between @ white)
        rotation = vecs[:, ::-1]
        self.center_ = center.astype(np.float32)
        self.projection_ = (white @ rotation).astype(np.float32)
        self.covariance_ = (corr * np.outer(self._std, self._std)).astype(np.float32)
        self.shrinkage_ = shrink

    def _modes(self, e: np.ndarray, y: np.ndarray, n_classes: int) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's subclass, and each subclass's class: classes split recursively by
        2-means while a split keeps at most ``split_ratio`` of the spread."""
        sub = np.empty(len(y), np.int64)
        owner: list[int] = []
        order = np.argsort(y, kind="stable")
        bounds = np.searchsorted(y[order], np.arange(n_classes + 1))
        for c in range(n_classes):
            rows = order[bounds[c] : bounds[c + 1]]
            for part in self._split(e, rows, self.max_modes):
                sub[part] = len(owner)
                owner.append(c)
        return sub, np.asarray(owner, np.int64)

    def _split(self, e: np.ndarray, rows: np.ndarray, budget: int) -> list[np.ndarray]:
        if budget < 2 or len(rows) < 2 * self.min_mode_samples:
            return [rows]
        x = e[rows].astype(np.float64)
        whole = ((x - x.mean(axis=0)) ** 2).sum()
        halves = _two_means(x)
        if halves is None or whole <= 0:
            return [rows]
        a, b = halves
        if min(a.sum(), b.sum()) < self.min_mode_samples:
            return [rows]
        parts = ((x[a] - x[a].mean(axis=0)) ** 2).sum() + ((x[b] - x[b].mean(axis=0)) ** 2).sum()
        if parts > self.split_ratio * whole:
            return [rows]
        left = self._split(e, rows[a], budget - 1)
        return left + self._split(e, rows[b], budget - len(left))


def _two_means(x: np.ndarray, rounds: int = 10) -> tuple[np.ndarray, np.ndarray] | None:
    """Lloyd's 2-means from the two points farthest apart (one pass each way)."""
    first = int(((x - x.mean(axis=0)) ** 2).sum(axis=1).argmax())
    second = int(((x - x[first]) ** 2).sum(axis=1).argmax())
    centres = x[[first, second]]
    side = None
    for _ in range(rounds):
        d = ((x[:, None, :] - centres[None]) ** 2).sum(axis=2)
        new = d[:, 1] < d[:, 0]
        if side is not None and (new == side).all():
            break
        side = new
        if side.all() or not side.any():
            return None
        centres = np.stack([x[~side].mean(axis=0), x[side].mean(axis=0)])
    return ~side, side
