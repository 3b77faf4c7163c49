"""Training sets for FC_Z from attributes: GEN-F (generated features) and NEIGHB-F."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from app.framework.generator import noisy


@torch.no_grad()
def generate_features(
    generator: nn.Module,
    attributes: np.ndarray,
    per_class: int,
    noise_std: float = 0.1,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """GEN-F: ``per_class`` features G(a_z + ns) for each row a_z; returns (features, labels)."""
    gen = torch.Generator().manual_seed(seed)
    a = torch.as_tensor(attributes, dtype=torch.float32).repeat_interleave(per_class, dim=0)
    generator.eval()
    feats = generator(noisy(a, noise_std, gen)).numpy()
    return feats, np.repeat(np.arange(len(attributes)), per_class)


def l1_nearest(queries: np.ndarray, pool: np.ndarray, k: int = 1, chunk: int = 256) -> np.ndarray:
    """Indices (Q, k) of the k L1-nearest rows of ``pool`` for each query row."""
    pool_t = torch.as_tensor(pool, dtype=torch.float32)
    k = min(k, len(pool))
    out = []
    for q in torch.as_tensor(queries, dtype=torch.float32).split(chunk):
        out.append(torch.cdist(q, pool_t, p=1).topk(k, largest=False).indices)
    return torch.cat(out).numpy()


def nearest_real_features(generated: np.ndarray, real_features: np.ndarray) -> np.ndarray:
    """NEIGHB-F: replace each generated feature by its L1-nearest real training feature."""
    return real_features[l1_nearest(generated, real_features, k=1)[:, 0]]
