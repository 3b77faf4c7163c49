"""Groups of samples answered as one object: the fingers of one trial, several touches of
one thing. ``recognize_batch`` with ``groups`` fuses each group's scores by ``fuse_groups``
(rule ``FUSION_RULE``) before routing and ranking them."""

from __future__ import annotations

from typing import Any

import numpy as np

from app.framework.errors import InputShapeError

#: how ``recognize_batch`` fuses the samples of a group (see ``fuse_groups``)
FUSION_RULE = "mean"


def check_groups(groups: Any, n: int) -> np.ndarray:
    """``groups`` as int64 (n,) with values 0 … G-1, every one used; InputShapeError if not."""
    try:
        g = np.asarray(groups)
    except (TypeError, ValueError):
        raise InputShapeError("groups must be an array of integers") from None
    if g.shape != (n,):
        raise InputShapeError(f"groups must have one entry per sample, shape ({n},), got {g.shape}")
    if g.dtype.kind not in "iu" and not (
        g.dtype.kind == "f" and np.isfinite(g).all() and (g == np.round(g)).all()
    ):
        raise InputShapeError(f"groups must be integers, got {g.dtype.name} values")
    g = g.astype(np.int64)
    if g.min() < 0:
        raise InputShapeError(f"groups must be 0 … G-1, got {int(g.min())}")
    used = np.bincount(g)
    if (used == 0).any():
        missing = int(np.argmin(used))
        raise InputShapeError(
            f"groups must number the groups 0 … G-1 with every group used; group {missing} "
            f"has no sample (G = {len(used)})"
        )
    return g


def group_mean(values: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """float64 mean of ``values`` (N, ...) over the rows of each group 0 … n_groups-1."""
    values = np.asarray(values, np.float64)
    out = np.zeros((n_groups, *values.shape[1:]))
    np.add.at(out, groups, values)
    counts = np.bincount(groups, minlength=n_groups).astype(np.float64)
    return out / counts.reshape(-1, *([1] * (values.ndim - 1)))


def fuse_groups(
    groups: np.ndarray,
    scores: np.ndarray,
    known_p: np.ndarray,
    novel_p: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The evidence of each group's samples as one answer (rule ``FUSION_RULE``, "mean"):
    the mean of the novelty scores, of the known-class probabilities and of the
    novel-class probabilities over the group's samples (each mean of probabilities is a
    distribution again). On the BioTac pilot's validation trials, fusing the two fingers by
    the product of their probabilities instead gave the same trial accuracy for ``best``
    and differed by a few hundredths either way for the other methods (docs/RESULTS.md);
    the mean is kept: one finger that is confidently wrong cannot veto the other."""
    n_groups = int(groups.max()) + 1
    return (
        group_mean(scores, groups, n_groups),
        group_mean(known_p, groups, n_groups),
        None if novel_p is None else group_mean(novel_p, groups, n_groups),
    )
