"""Robust input scaling: tactile features span many orders of magnitude (PHAC-2 up to 1e10)."""

from __future__ import annotations

import numpy as np


def flatten(samples: np.ndarray) -> np.ndarray:
    """Samples as flat float32 vectors (N, D): a C x T tactile image becomes one row."""
    return np.asarray(samples, dtype=np.float32).reshape(len(samples), -1)


class RobustInputScaler:
    """sign(x)·log1p(|x|), then centre by the median and divide by a robust spread, then clip.

    Statistics are per feature for flat inputs (N, D) and per channel for tactile
    images (N, C, T), so a channel's time course keeps its shape.
    """

    def __init__(self, log_compress: bool = True, clip: float = 8.0) -> None:
        self.log_compress = log_compress
        self.clip = clip
        self.center_: np.ndarray | None = None
        self.scale_: np.ndarray | None = None

    def _compress(self, x: np.ndarray, dtype=np.float64) -> np.ndarray:
        x = np.asarray(x, dtype=dtype)
        if not self.log_compress:
            return x.copy()
        z = np.abs(x)  # the only new array: the rest is in place
        np.log1p(z, out=z)
        return np.copysign(z, x, out=z)

    def _axes(self, x: np.ndarray) -> tuple[int, ...]:
        return (0,) if x.ndim == 2 else (0, 2)

    def fit(self, x: np.ndarray) -> RobustInputScaler:
        z = self._compress(x)
        axes = self._axes(z)
        center = np.median(z, axis=axes, keepdims=True)
        q75, q25 = np.percentile(z, [75, 25], axis=axes, keepdims=True)
        scale = (q75 - q25) / 1.349
        std = z.std(axis=axes, keepdims=True)
        # constant or near-constant features fall back to the std, then to 1
        scale = np.where(scale > 1e-8, scale, np.where(std > 1e-8, std, 1.0))
        self.center_ = center[0].astype(np.float32)
        self.scale_ = scale[0].astype(np.float32)
        return self

    def transform(self, x: np.ndarray) -> np.ndarray:
        # float32 on the recognition path: twice as fast, and the clip bounds the error
        z = self._compress(x, np.float32)
        z -= self.center_
        z /= self.scale_
        return np.clip(z, -self.clip, self.clip, out=z)

    def fit_transform(self, x: np.ndarray) -> np.ndarray:
        return self.fit(x).transform(x)

    def get_state(self) -> dict[str, np.ndarray]:
        return {"center": self.center_, "scale": self.scale_}

    def set_state(self, arrays: dict[str, np.ndarray]) -> None:
        self.center_ = np.asarray(arrays["center"], np.float32)
        self.scale_ = np.asarray(arrays["scale"], np.float32)


class BlockPCA:
    """Principal components of scaled inputs, taken within each of ``n_blocks`` equal,
    contiguous blocks of features (one per exploratory procedure, or one for all): a sample's
    reduced coordinates keep its procedures apart, block after block, so a model of them can
    still answer from some procedures.

    Each block keeps ``ceil(n_components / n_blocks)`` components, at most its own features
    and one fewer than the rows it is fitted on. ``truncated`` keeps each block's leading
    ones. The components come from at most ``max_rows`` rows drawn at random (``seed``),
    through scikit-learn's ``PCA`` (its ``svd_solver="auto"``, seeded).
    """

    def __init__(
        self, n_components: int, n_blocks: int = 1, seed: int = 0, max_rows: int = 50_000
    ) -> None:
        self.n_components = n_components
        self.n_blocks = n_blocks
        self.seed = seed
        self.max_rows = max_rows

    def fit(self, z: np.ndarray) -> BlockPCA:
        from sklearn.decomposition import PCA

        n, d = z.shape
        if self.n_blocks < 1 or d % self.n_blocks:
            raise ValueError(f"{d} features do not split into {self.n_blocks} equal blocks")
        rng = np.random.default_rng(self.seed)
        rows = np.sort(rng.choice(n, min(n, self.max_rows), replace=False))
        width = d // self.n_blocks
        keep = min(-(-int(self.n_components) // self.n_blocks), width, max(len(rows) - 1, 1))
        self.mean_ = np.asarray(z[rows].mean(axis=0), np.float32)
        components = np.empty((self.n_blocks, keep, width), np.float32)
        for b in range(self.n_blocks):
            part = np.asarray(z[rows, b * width : (b + 1) * width], np.float32)
            pca = PCA(keep, svd_solver="auto", random_state=self.seed).fit(part)
            components[b] = pca.components_
        self.components_ = components
        return self

    @property
    def n_features_in(self) -> int:
        return int(self.components_.shape[0] * self.components_.shape[2])

    @property
    def n_features_out(self) -> int:
        return int(self.components_.shape[0] * self.components_.shape[1])

    def truncated(self, n_components: int) -> BlockPCA:
        """The same fit keeping each block's leading ``ceil(n_components / n_blocks)``."""
        new = BlockPCA(n_components, self.n_blocks, self.seed, self.max_rows)
        keep = -(-int(n_components) // self.n_blocks)
        new.mean_, new.components_ = self.mean_, self.components_[:, :keep]
        return new

    def transform(self, z: np.ndarray) -> np.ndarray:
        """(N, n_blocks x components a block) float32 coordinates, block after block."""
        blocks, keep, width = self.components_.shape
        out = np.empty((len(z), blocks * keep), np.float32)
        for b in range(blocks):
            part = np.asarray(z[:, b * width : (b + 1) * width], np.float32)
            part = part - self.mean_[b * width : (b + 1) * width]
            out[:, b * keep : (b + 1) * keep] = part @ self.components_[b].T
        return out

    def get_state(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "components": self.components_}

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray]) -> BlockPCA:
        components = np.asarray(arrays["components"], np.float32)
        new = cls(components.shape[0] * components.shape[1], components.shape[0])
        new.mean_, new.components_ = np.asarray(arrays["mean"], np.float32), components
        return new
