"""One-shot learning (Sect. IV-F): each real sample of a novel class trains FC_Z
together with its k nearest real features, so one sample counts as k + 1."""

from __future__ import annotations

import numpy as np


def one_shot_training_set(
    sample_features: np.ndarray, sample_labels: np.ndarray, real_features: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """(features, labels): every f_l plus its k L1-nearest real training features, labelled z_l."""
    if len(sample_features) == 0:
        return sample_features, sample_labels
    if k <= 0:
        return sample_features, sample_labels
    # here, not at the top: best and prototypes import this module's bounds and answer
    # without torch, which synthesis loads
    from app.framework.synthesis import l1_nearest

    nn_idx = l1_nearest(sample_features, real_features, k=k)
    feats = np.concatenate([sample_features[:, None, :], real_features[nn_idx]], axis=1)
    labels = np.repeat(sample_labels, nn_idx.shape[1] + 1)
    return feats.reshape(-1, sample_features.shape[1]), labels


def shot_penalty(margin: float, counts: np.ndarray) -> np.ndarray:
    """(S,) the score a class learnt from ``counts`` samples gives up: ``margin / n``, an
    uncertainty that shrinks as its samples grow (one sample pays it whole)."""
    return float(margin) / np.maximum(np.asarray(counts, np.float64), 1.0)


def bounded_shots(
    novel: np.ndarray, has: np.ndarray, shot_logits: np.ndarray, rival_logits: np.ndarray
) -> np.ndarray:
    """The novel classes' probabilities ``novel`` (N, L), in which the classes with samples
    (``has``, L bools) share a mass they need not earn (their zero-shot probability, which
    for a class without a description is a neutral score), with that mass bounded by how
    close each touch lies to their samples.

    ``shot_logits`` (N, S): each class with samples' log score for the touch (closeness to
    its samples, less ``shot_penalty``); ``rival_logits`` (N,): the same score of the touch's
    closest known class, on the same scale. The classes with samples keep the share
    ``sum exp(shot) / (sum exp(shot) + exp(rival))`` of their mass, split among them as in
    ``novel``; what they give up goes to the classes without samples in proportion to their
    probabilities. So a class learnt from one sample takes a touch only where the touch is
    clearly closer to that sample than to every known object. Rows in which the classes
    without samples hold no probability keep the mass where it was (there is no one to give
    it to), and so does a model whose novel classes all have samples, or none."""
    has = np.asarray(has, bool)
    if not has.any() or has.all():
        return novel
    shot = np.asarray(shot_logits, np.float64)
    rival = np.asarray(rival_logits, np.float64)[:, None]
    top = np.maximum(shot.max(axis=1, keepdims=True), rival)
    w = np.exp(shot - top).sum(axis=1, keepdims=True)
    kept = w / (w + np.exp(rival - top))
    mass = novel[:, has].sum(axis=1, keepdims=True)
    others = novel[:, ~has]
    held = others.sum(axis=1, keepdims=True)
    out = np.array(novel, np.float64, copy=True)
    out[:, has] = novel[:, has] * kept
    out[:, ~has] = others * (1.0 + mass * (1.0 - kept) / np.where(held > 0, held, 1.0))
    keep = (held[:, 0] <= 0) | ~np.isfinite(out).all(axis=1)
    out[keep] = novel[keep]
    return out
