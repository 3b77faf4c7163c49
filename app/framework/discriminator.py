"""D: real (CONV_XF) or synthetic (G) feature -> one logit (Table I)."""

from __future__ import annotations

import torch
from torch import nn


def _xavier(module: nn.Module) -> None:
    for m in module.modules():
        if isinstance(m, nn.Conv1d | nn.Linear):
            nn.init.xavier_uniform_(m.weight)
            nn.init.zeros_(m.bias)


class ConvFeatureDiscriminator(nn.Module):
    """(256, T'') -> (96, ·) -> (1, ·) -> mean: two stride-2 convolutions, kernel (3, 1)."""

    def __init__(self, feature_shape: tuple[int, int], hidden: int = 96) -> None:
        super().__init__()
        channels, length = feature_shape
        self.feature_shape = feature_shape
        k1 = min(3, length)
        t1 = (length - k1) // 2 + 1
        k2 = min(3, t1)
        self.net = nn.Sequential(
            nn.Conv1d(channels, hidden, k1, stride=2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(hidden, 1, k2, stride=2),
        )
        _xavier(self)

    def forward(self, f: torch.Tensor) -> torch.Tensor:  # (N, F) -> (N,)
        return self.net(f.view(len(f), *self.feature_shape)).mean(dim=(1, 2))


class MLPFeatureDiscriminator(nn.Module):
    def __init__(self, feature_dim: int, hidden: int = 128) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(feature_dim, hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, 1)
        )
        _xavier(self)

    def forward(self, f: torch.Tensor) -> torch.Tensor:
        return self.net(f)[:, 0]


def build_discriminator(feature_shape: tuple[int, ...]) -> nn.Module:
    if len(feature_shape) == 2:
        return ConvFeatureDiscriminator(feature_shape)
    return MLPFeatureDiscriminator(feature_shape[0])
