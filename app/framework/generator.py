"""G: attribute vector (+ N(0, 0.1) noise) -> synthetic feature f_gen in F (Table I)."""

from __future__ import annotations

import torch
from torch import nn


def _gaussian(module: nn.Module, std: float = 0.02) -> None:
    for m in module.modules():
        if isinstance(m, nn.ConvTranspose1d | nn.Linear):
            nn.init.normal_(m.weight, 0.0, std)
            nn.init.zeros_(m.bias)


class DeconvFeatureGenerator(nn.Module):
    """Two transposed convolutions: (M, 1) -> (96, k1) -> (256, T'') for conv features.

    Table I: 96 then 256 channels, kernels (4, 1) and (3, 1), strides 2 and 1;
    with T'' = 6 the kernels are exactly the paper's. Gaussian initialisation.
    The output passes a ReLU because real CONV_XF features do.
    """

    def __init__(self, n_attributes: int, feature_shape: tuple[int, int], hidden: int = 96) -> None:
        super().__init__()
        channels, length = feature_shape
        k1 = min(4, length)
        k2 = length - k1 + 1  # (1 - 1) * 2 + k1 = k1, then k1 + k2 - 1 = length
        self.net = nn.Sequential(
            nn.ConvTranspose1d(n_attributes, hidden, k1, stride=2),
            nn.ReLU(),
            nn.ConvTranspose1d(hidden, channels, k2, stride=1),
            nn.ReLU(),
        )
        _gaussian(self)

    def forward(self, attributes: torch.Tensor) -> torch.Tensor:  # (N, M) -> (N, F)
        return self.net(attributes[:, :, None]).flatten(1)


class MLPFeatureGenerator(nn.Module):
    """(N, M) -> (N, F) for flat-feature models; same role as the deconvolutional G."""

    def __init__(self, n_attributes: int, feature_dim: int, hidden: int = 256) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(n_attributes, hidden),
            nn.LeakyReLU(0.2),
            nn.Linear(hidden, feature_dim),
            nn.ReLU(),
        )
        _gaussian(self, std=0.1)

    def forward(self, attributes: torch.Tensor) -> torch.Tensor:
        return self.net(attributes)


def build_generator(n_attributes: int, feature_shape: tuple[int, ...]) -> nn.Module:
    if len(feature_shape) == 2:
        return DeconvFeatureGenerator(n_attributes, feature_shape)
    return MLPFeatureGenerator(n_attributes, feature_shape[0])


def noisy(attributes: torch.Tensor, std: float, gen: torch.Generator | None = None) -> torch.Tensor:
    """a + ns, ns ~ N(0, std): Algorithm 1 line 4-5."""
    return attributes + std * torch.randn(attributes.shape, generator=gen)
