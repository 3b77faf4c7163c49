"""CONV_XF: the feature extractor x -> f_ext (Table I), and an MLP twin for flat features."""

from __future__ import annotations

import math

import torch
from torch import nn


def _xavier(module: nn.Module) -> None:
    for m in module.modules():
        if isinstance(m, nn.Conv1d | nn.Linear):
            nn.init.xavier_uniform_(m.weight)
            nn.init.zeros_(m.bias)


def grouped_conv1d(x: torch.Tensor, conv: nn.Conv1d) -> torch.Tensor:
    """The same result as ``conv(x)``, computed as one batched matmul over groups.

    With one input channel per group, oneDNN's grouped convolution is slow on CPU;
    unfold + bmm is about 2x faster at any batch size (bench/bench_framework.py).
    """
    g, (k,), (s,) = conv.groups, conv.kernel_size, conv.stride
    n, c, _ = x.shape
    out = conv.out_channels
    u = x.unfold(2, k, s)  # (N, C, T', k)
    t = u.shape[2]
    u = u.reshape(n, g, c // g, t, k).permute(1, 0, 3, 2, 4).reshape(g, n * t, (c // g) * k)
    w = conv.weight.reshape(g, out // g, (c // g) * k).transpose(1, 2)
    y = torch.bmm(u, w).reshape(g, n, t, out // g).permute(1, 0, 3, 2).reshape(n, out, t)
    return y + conv.bias[None, :, None]


class ConvFeatureExtractor(nn.Module):
    """Two grouped 1-D convolutions over time, (C, T) -> (256, T'') flattened.

    Table I: 96 then 256 channels, kernel (3, 1), stride 2, 32 groups, ReLU.
    For a 32 x 30 tactile image T'' = 6, so F = 256 x 6 = 1536. The group count is
    the largest divisor of 32 that also divides C, so any channel count works.
    """

    def __init__(
        self,
        in_channels: int,
        length: int,
        channels=(96, 256),
        kernel: int = 3,
        stride: int = 2,
        groups: int = 32,
    ) -> None:
        super().__init__()
        g = math.gcd(in_channels, groups)
        self.net = nn.Sequential(
            nn.Conv1d(in_channels, channels[0], kernel, stride=stride, groups=g),
            nn.ReLU(),
            nn.Conv1d(channels[0], channels[1], kernel, stride=stride, groups=g),
            nn.ReLU(),
        )
        t = length
        for _ in range(2):
            t = (t - kernel) // stride + 1
        if t < 1:
            raise ValueError(
                f"time axis of length {length} is too short for two stride-{stride} convolutions"
            )
        self.feature_shape = (channels[1], t)
        self.feature_dim = channels[1] * t
        _xavier(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (N, C, T) -> (N, F)
        conv1, relu, conv2, _ = self.net
        return torch.relu(grouped_conv1d(relu(grouped_conv1d(x, conv1)), conv2)).flatten(1)


class MLPFeatureExtractor(nn.Module):
    """Flat features (N, D) -> (N, F): two ReLU layers with dropout for small datasets."""

    def __init__(
        self, in_features: int, hidden: int = 256, feature_dim: int = 128, dropout: float = 0.2
    ) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Dropout(dropout / 2),
            nn.Linear(in_features, hidden),
            nn.ReLU(),
            nn.Dropout(dropout),
            nn.Linear(hidden, feature_dim),
            nn.ReLU(),
        )
        self.feature_shape = (feature_dim,)
        self.feature_dim = feature_dim
        _xavier(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def build_encoder(
    input_shape: tuple[int, ...],
    mlp_hidden: int = 256,
    mlp_features: int = 128,
    mlp_dropout: float = 0.5,
) -> nn.Module:
    """CONV_XF for (C, T) tactile images, the MLP twin for (D,) flat features."""
    if len(input_shape) == 2:
        return ConvFeatureExtractor(input_shape[0], input_shape[1])
    if len(input_shape) == 1:
        return MLPFeatureExtractor(input_shape[0], mlp_hidden, mlp_features, mlp_dropout)
    raise ValueError(f"input shape must be (C, T) or (D,), got {input_shape}")
