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
