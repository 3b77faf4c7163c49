"""One-shot learning (Sect. IV-F): each real sample of a novel class trains FC_Z
together with its k nearest real features, so one sample counts as k + 1."""

from __future__ import annotations

import numpy as np

from app.framework.synthesis import l1_nearest


def one_shot_training_set(
    sample_features: np.ndarray, sample_labels: np.ndarray, real_features: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """(features, labels): every f_l plus its k L1-nearest real training features, labelled z_l."""
    if len(sample_features) == 0:
        return sample_features, sample_labels
    if k <= 0:
        return sample_features, sample_labels
    nn_idx = l1_nearest(sample_features, real_features, k=k)
    feats = np.concatenate([sample_features[:, None, :], real_features[nn_idx]], axis=1)
    labels = np.repeat(sample_labels, nn_idx.shape[1] + 1)
    return feats.reshape(-1, sample_features.shape[1]), labels
