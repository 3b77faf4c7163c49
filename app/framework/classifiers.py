"""FC_Y (known objects) and FC_Z (novel objects): one fully connected layer each (Sect. V-B)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class FullyConnectedClassifier(nn.Module):
    """Features (N, F) -> class logits (N, n_classes); Xavier-initialised."""

    def __init__(self, feature_dim: int, n_classes: int) -> None:
        super().__init__()
        self.linear = nn.Linear(feature_dim, n_classes)
        nn.init.xavier_uniform_(self.linear.weight)
        nn.init.zeros_(self.linear.bias)

    def forward(self, f: torch.Tensor) -> torch.Tensor:
        return self.linear(f)


def fit_classifier(
    classifier: nn.Module,
    features: np.ndarray,
    labels: np.ndarray,
    epochs: int,
    lr: float = 1e-2,
    weight_decay: float = 1e-4,
    batch_size: int = 50,
    seed: int = 0,
) -> nn.Module:
    """Train a classifier on fixed features with softmax + multinomial logistic loss."""
    gen = torch.Generator().manual_seed(seed)
    f = torch.as_tensor(features, dtype=torch.float32)
    y = torch.as_tensor(labels, dtype=torch.long)
    opt = torch.optim.Adam(classifier.parameters(), lr=lr, weight_decay=weight_decay)
    loss_fn = nn.CrossEntropyLoss()
    classifier.train()
    n = len(f)
    for _ in range(epochs):
        for idx in torch.randperm(n, generator=gen).split(batch_size):
            opt.zero_grad()
            loss_fn(classifier(f[idx]), y[idx]).backward()
            opt.step()
    classifier.eval()
    return classifier
