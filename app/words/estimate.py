"""Values for the attributes a description does not mention, estimated from what it says.

A sentence names a few attributes ("soft, squishy foam"); the known classes show which
attributes go together (soft, squishy things are mostly compressible and not metallic).
``UnmentionedEstimator`` weighs each known class by how well its vector matches the values
read, and gives every attribute the text is silent on the weighted mean of the known
classes' values. These are estimates, kept apart from what the text says: the reader marks
them ``source="estimated"`` and never lets one override a value read.

The kernel width is fixed a priori, not tuned on PHAC-2: with ``width`` 0.5 a known class
that disagrees with one value read (a squared difference of 0.81 for 0.9 against 0) keeps
e^(-0.81/0.5) ≈ 0.2 of the weight of one that agrees.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from app.words.interpret import Reading


class UnmentionedEstimator:
    """Estimates unmentioned attributes from known classes' vectors.

    Parameters
    ----------
    width : float, default 0.5
        Kernel width: a known class's weight is exp(-Σ (read - its value)² / width) over the
        attributes read (its values not known are left out of the sum).
    """

    def __init__(self, width: float = 0.5) -> None:
        self.width = width

    def fit(self, class_vectors: np.ndarray, attributes: Sequence[str]) -> UnmentionedEstimator:
        """``class_vectors`` (K, M): the known classes' values, NaN where not known."""
        vectors = np.asarray(class_vectors, np.float64)
        if vectors.ndim != 2 or vectors.shape[1] != len(attributes):
            raise ValueError(
                f"expected one value per attribute ({len(attributes)}) for each known class, "
                f"got shape {vectors.shape}"
            )
        if len(vectors) == 0:
            raise ValueError("no known class to estimate from")
        if not self.width > 0:
            raise ValueError(f"width must be above 0, got {self.width}")
        self.class_vectors_ = vectors
        self.attributes_ = list(attributes)
        return self

    def estimate(self, read: Mapping[str, float]) -> dict[str, float]:
        """Attribute -> estimated value in [0, 1], for the fitted attributes not in ``read``
        that at least one known class has a value for. Empty when nothing read is known
        to the fitted attributes (there is nothing to estimate from)."""
        index = {a: j for j, a in enumerate(self.attributes_)}
        said = [(index[a], float(v)) for a, v in read.items() if a in index]
        if not said:
            return {}
        cols = np.array([j for j, _ in said])
        values = np.array([v for _, v in said])
        diff = self.class_vectors_[:, cols] - values[None, :]
        distance = np.nansum(diff**2, axis=1)
        weight = np.exp(-(distance - distance.min()) / self.width)
        out = {}
        for j, attribute in enumerate(self.attributes_):
            if attribute in read:
                continue
            column = self.class_vectors_[:, j]
            known = ~np.isnan(column)
            if known.any():
                w = weight[known]
                out[attribute] = round(float(np.clip(w @ column[known] / w.sum(), 0.0, 1.0)), 3)
        return out


def estimated_readings(
    read: Mapping[str, Reading], estimator: UnmentionedEstimator
) -> dict[str, Reading]:
    """``Reading``s (source ``"estimated"``) for the fitted attributes ``read`` is silent on,
    their ``words`` naming the attributes read that they follow from."""
    from app.words.interpret import Reading

    said = {a: r.value for a, r in read.items()}
    basis = "estimated from " + ", ".join(sorted(said)) + " and the known classes"
    return {a: Reading(a, v, basis, "estimated") for a, v in estimator.estimate(said).items()}
