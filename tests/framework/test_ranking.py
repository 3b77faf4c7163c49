"""``ranked``: the top k of each row, largest first, equal values by lower index, whether the
row is short (a stable sort) or wide (a partition, then a sort of the candidates only)."""

from __future__ import annotations

import numpy as np
import pytest

from app.framework.recognizer import ranked


@pytest.mark.parametrize("width", [1, 5, 60, 200, 3000])
@pytest.mark.parametrize("k", [1, 3, 40])
def test_ranked_is_a_stable_descending_sort(width, k):
    rng = np.random.default_rng(width * 100 + k)
    # few distinct values: many ties, also across the k-th place
    p = rng.integers(0, 4, (7, width)) / 4.0
    p[0] = 0.0  # a row of equal values
    expected = np.argsort(-p, axis=1, kind="stable")[:, : min(k, width)]
    assert np.array_equal(ranked(p, k), expected)


def test_ranked_on_a_wide_posterior_keeps_the_largest():
    rng = np.random.default_rng(0)
    p = rng.dirichlet(np.full(30_000, 0.01), size=3)
    out = ranked(p, 3)
    assert out.shape == (3, 3)
    for row, idx in zip(p, out, strict=True):
        assert np.array_equal(row[idx], np.sort(row)[::-1][:3])
