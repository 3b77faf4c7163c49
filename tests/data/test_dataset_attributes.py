"""TactileDataset's attribute values: graded, not known and absent are carried, and every
recognition method refuses them with an error that says why instead of training on them."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.dataset import DatasetError, TactileDataset
from app.data.simulator import simulate_dataset
from app.evaluation.splits import make_zsl_splits
from app.framework.registry import METHODS, make_method, method_class


def with_values(values: np.ndarray, names: tuple[str, ...] | None = None) -> TactileDataset:
    ds = simulate_dataset(n_objects=6, seed=0)
    names = ("hard", "soft", "rough")[: values.shape[1]] if names is None else names
    return TactileDataset(ds.samples, ds.labels, ds.trials, values, names, ds.class_names)


def test_binary_attributes_read_as_before():
    ds = simulate_dataset(n_objects=6, seed=0)
    assert ds.binary_attributes
    assert ds.class_attributes is ds.attribute_values
    assert np.isin(ds.class_attributes, (0, 1)).all()


def test_graded_and_not_known_values_are_kept_but_not_handed_to_methods():
    values = np.tile([1.0, 0.0, 0.5], (6, 1))
    values[3, 1] = np.nan
    ds = with_values(values)
    assert not ds.binary_attributes
    np.testing.assert_array_equal(ds.attribute_values, values.astype(np.float32))
    with pytest.raises(
        DatasetError,
        match=r"graded or not-known attribute values \(7 of 18; "
        r"class 'sim-object-00', attribute 'rough' is 0.5\)",
    ):
        _ = ds.class_attributes
    sub = ds.select_classes([3])
    assert np.isnan(sub.attribute_values[0, 1]) and len(ds.subset(ds.labels == 3)) == len(sub)


def test_no_attribute_columns():
    ds = with_values(np.zeros((6, 0)), ())
    assert ds.n_attributes == 0 and not ds.binary_attributes
    with pytest.raises(DatasetError, match="has no attributes"):
        _ = ds.class_attributes


def test_values_outside_zero_one_are_rejected():
    with pytest.raises(DatasetError, match="must lie in \\[0, 1\\].*attribute 'soft' is 2.0"):
        with_values(np.tile([1.0, 2.0], (6, 1)))
    with pytest.raises(DatasetError, match="attribute names must be unique; repeated: a"):
        with_values(np.ones((6, 2)), ("a", "a"))


@pytest.mark.parametrize(
    "method", sorted(m for m in METHODS if not method_class(m).graded_attributes)
)
def test_methods_of_0_1_attributes_refuse_graded_values_before_training(method):
    ds = with_values(np.full((6, 3), 0.5))
    with pytest.raises(DatasetError, match="graded or not-known attribute values"):
        make_method(method).fit(ds)


def test_the_methods_that_take_graded_values_are_named():
    graded = sorted(m for m in METHODS if method_class(m).graded_attributes)
    assert graded == ["auto", "best", "paper", "paper-fgmm", "prototypes"]


def test_evaluation_splits_refuse_datasets_without_attributes():
    with pytest.raises(DatasetError, match="has no attributes"):
        make_zsl_splits(with_values(np.zeros((6, 0)), ()), n_novel=2, n_splits=1, seed=0)
