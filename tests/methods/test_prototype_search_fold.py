"""Prototypes added after the fit are folded into a copy of the index past ``fold_above``:
the same neighbours as before the fold, the search they came from untouched, and a bundle
of a model whose promotions were folded answers as the model did."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.methods.prototype_search import PrototypeSearch
from app.methods.prototypes import PrototypeRecognizer


def _grown(search: PrototypeSearch, extra: np.ndarray) -> list[PrototypeSearch]:
    out = [search]
    for row in extra:
        out.append(out[-1].with_points(row[None]))
    return out


@pytest.mark.parametrize("exact_below", [10_000, 0], ids=["exact", "hnsw"])
def test_folded_points_are_found_as_points_beside_the_index_are(exact_below):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(400, 32)).astype(np.float32)
    extra = rng.normal(size=(9, 32)).astype(np.float32)
    queries = np.concatenate([extra + 0.01, rng.normal(size=(50, 32)).astype(np.float32)])
    folding = _grown(PrototypeSearch(points, exact_below, fold_above=4), extra)
    beside = _grown(PrototypeSearch(points, exact_below, fold_above=100), extra)
    # 4 wait beside the index; the 5th folds all 5 in; 4 more wait again
    assert [len(s.extra) for s in folding] == [0, 1, 2, 3, 4, 0, 1, 2, 3, 4]
    assert [s.index.ntotal for s in folding][-1] == 405 and len(folding[-1]) == 409
    assert all(len(s.extra) == i for i, s in enumerate(beside))
    ids_f, d_f = folding[-1].nearest(queries, 8)
    ids_b, d_b = beside[-1].nearest(queries, 8)
    assert ids_f[:9, 0].tolist() == list(range(400, 409))  # each added point finds itself
    if exact_below:  # an exact search: the same neighbours at the same distances
        assert np.array_equal(ids_f, ids_b)
        np.testing.assert_allclose(d_f, d_b, rtol=1e-6)
    # the searches before the fold kept their index and their points
    assert folding[4].index.ntotal == 400 and len(folding[4]) == 404
    ids_4, _ = folding[4].nearest(extra[:4] + 0.01, 1)
    assert ids_4[:, 0].tolist() == [400, 401, 402, 403]
    assert folding[0].index is folding[4].index is not folding[5].index
    if not exact_below:
        assert folding[-1].index.hnsw.efSearch == folding[0].index.hnsw.efSearch


def test_a_negative_bound_is_refused():
    with pytest.raises(ValueError, match="fold_above must be a non-negative integer"):
        PrototypeSearch(np.zeros((3, 4), np.float32), fold_above=-1)


def test_a_model_whose_promotions_were_folded_reads_back_with_the_same_answers():
    ds = simulate_dataset(30, 4, seed=3)
    fitted = 24
    base = PrototypeRecognizer(seed=0).fit(
        ds.subset(np.flatnonzero(ds.labels < fitted)).select_classes(np.arange(fitted))
    )
    base.search_.fold_above = 2  # the fitted model's search: its promotions fold early
    model = base
    for c in range(fitted, 30):
        name = ds.class_names[c]
        model = model.with_known_samples(
            {name: ds.samples[ds.labels == c]}, {name: ds.class_attributes[c]}
        )
    assert model.search_.index is not base.search_.index
    assert len(model.search_) == len(base.search_) + 6 and len(model.search_.extra) < 3
    back = bundle.from_bytes(bundle.to_bytes(model))
    x = ds.samples[::2]
    a, b = model.recognize_batch(x), back.recognize_batch(x)
    assert np.array_equal(a.top_index, b.top_index)
    np.testing.assert_allclose(a.novelty_score, b.novelty_score, rtol=1e-6)
    promoted = ds.labels[::2] >= fitted
    found = np.array(model.registry.known_names)[model.known_proba(x).argmax(axis=1)]
    names = np.array(ds.class_names)[ds.labels[::2]]
    assert (found[promoted] == names[promoted]).mean() >= 0.9
