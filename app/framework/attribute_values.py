"""Attribute values beyond 0 and 1: graded values (in [0, 1]) and values not known (NaN).

A class's vector may say "somewhat soft" (0.5), or nothing at all about an attribute that
was added to the vocabulary after the class was described. Methods that learn attributes
per attribute leave the unknown values out; parts that need a whole vector (a semantic
autoencoder, the paper's generator G) are given the attribute's prior instead.
"""

from __future__ import annotations

import numpy as np


def attribute_prior(class_attributes: np.ndarray) -> np.ndarray:
    """(M,) p(a_m = 1): the mean of the known classes' values where known, 0.5 for an
    attribute no class has a value for."""
    given = np.asarray(class_attributes)
    known = ~np.isnan(given)
    if known.all():  # the common case: the plain mean, in the values' own precision
        return given.mean(axis=0).astype(np.float64)
    a = given.astype(np.float64)
    counts = known.sum(axis=0)
    sums = np.where(known, a, 0.0).sum(axis=0)
    return np.where(counts > 0, sums / np.maximum(counts, 1), 0.5)


def impute(class_attributes: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """The vectors with every value not known replaced by the attribute's prior: what
    parts that need a whole vector (the semantic autoencoder, a generator) are given."""
    a = np.asarray(class_attributes, np.float32)
    return np.where(np.isnan(a), np.asarray(prior, np.float32)[None, :], a).astype(np.float32)
