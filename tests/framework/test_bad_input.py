"""Every bad input gets a specific exception that names the problem, and changes nothing."""

import numpy as np
import pytest

from app.data.dataset import DatasetError, TactileDataset
from app.framework.errors import (
    AttributeVectorError,
    DuplicateClassError,
    InputShapeError,
    NonFiniteInputError,
    NotFittedError,
    UnknownClassError,
)
from app.framework.paper import PaperRecognizer


def test_wrong_sample_shape(fitted):
    with pytest.raises(
        InputShapeError, match=r"expected samples of shape \(N, 32, 30\), got \(2, 30, 32\)"
    ):
        fitted.recognize(np.zeros((2, 30, 32)))


def test_single_sample_without_batch_axis_is_accepted(fitted, sim_split):
    assert len(fitted.recognize(sim_split["test"].samples[0])) == 1


def test_empty_batch(fitted):
    with pytest.raises(InputShapeError, match="empty batch"):
        fitted.recognize(np.zeros((0, 32, 30)))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_values_name_the_sample(fitted, bad):
    x = np.zeros((3, 32, 30), np.float32)
    x[2, 5, 5] = bad
    with pytest.raises(NonFiniteInputError, match="sample 2"):
        fitted.recognize(x)


def test_non_numeric_samples(fitted):
    with pytest.raises(InputShapeError, match="not a numeric array"):
        fitted.recognize([["a"] * 30] * 32)


def test_unknown_attribute_names(fitted):
    with pytest.raises(AttributeVectorError, match="unknown attribute.*glowing") as raised:
        fitted.attribute_vector(["hard", "glowing"])
    assert "did you mean" not in str(raised.value)  # nothing like it in the vocabulary
    assert str(raised.value).endswith(", ".join(fitted.registry.attribute_names))


def test_a_misspelt_attribute_gets_the_closest_names(fitted):
    with pytest.raises(AttributeVectorError, match=r"'hrad' \(did you mean 'hard'\?\)"):
        fitted.attribute_vector(["hrad", "smooth"])


def test_attribute_vector_of_wrong_length(fitted):
    with pytest.raises(AttributeVectorError, match="length 19"):
        fitted.add_novel_classes(["thing"], [[1, 0, 1]])


def test_attribute_vector_with_values_outside_0_1(fitted):
    v = np.zeros(19)
    v[0] = 1.5
    with pytest.raises(AttributeVectorError, match=r"in \[0, 1\].*1.5"):
        fitted.add_novel_classes(["thing"], [v])


def test_a_method_of_0_1_attributes_refuses_graded_values():
    from app.baselines.dap import DAPRecognizer

    model = DAPRecognizer()
    model.registry.attribute_names = ("hard", "soft")
    with pytest.raises(AttributeVectorError, match="only 0 and 1.*'dap'"):
        model.validate_attribute_vectors([[0.5, 1.0]])


def test_all_zero_attribute_vector(fitted):
    with pytest.raises(AttributeVectorError, match="at least one attribute"):
        fitted.add_novel_classes(["thing"], [np.zeros(19)])


def test_vector_equal_to_an_existing_class(fitted):
    existing = fitted.registry.known_attributes[4]
    with pytest.raises(
        DuplicateClassError,
        match=f"same attribute vector as existing class '{fitted.registry.known_names[4]}'",
    ):
        fitted.add_novel_classes(["copy"], [existing])
    assert fitted.registry.novel_names == []  # nothing half-added


def test_duplicate_name(with_novel):
    name = with_novel.registry.novel_names[0]
    v = np.zeros(19)
    v[[0, 1, 2, 3, 4, 5]] = 1
    with pytest.raises(DuplicateClassError, match=f"'{name}' already exists"):
        with_novel.add_novel_classes([name], [v])


def test_two_new_classes_with_one_vector(fitted):
    v = np.zeros(19)
    v[[0, 2, 7, 9, 11, 13, 15]] = 1
    with pytest.raises(DuplicateClassError, match="same attribute vector"):
        fitted.add_novel_classes(["a", "b"], [v, v])


def test_one_shot_for_unknown_or_known_class(with_novel, sim_split):
    x = sim_split["novel"].samples[:1]
    with pytest.raises(UnknownClassError, match="unknown class 'nope'"):
        with_novel.add_one_shot("nope", x)
    with pytest.raises(UnknownClassError, match="is a known class"):
        with_novel.add_one_shot(with_novel.registry.known_names[0], x)


def test_novel_proba_without_novel_classes(fitted, sim_split):
    with pytest.raises(UnknownClassError, match="no novel classes"):
        fitted.novel_proba(sim_split["novel"].samples[:1])


def test_unfitted_model():
    with pytest.raises(NotFittedError, match="not fitted"):
        PaperRecognizer().recognize(np.zeros((1, 32, 30)))


def test_bad_hyper_parameter(sim_split):
    model = PaperRecognizer(synthesis="magic")  # the constructor only stores its arguments
    with pytest.raises(ValueError, match="synthesis must be one of"):
        model.fit(sim_split["train"])  # fit checks them before any work
    assert model.input_shape is None
    with pytest.raises(ValueError, match="alg1_epochs must be at least 1, got 0"):
        PaperRecognizer(alg1_epochs=0).fit(sim_split["train"])


def test_empty_dataset_is_rejected():
    with pytest.raises(DatasetError, match="no samples"):
        TactileDataset(
            np.zeros((0, 4)), np.zeros(0), np.zeros(0), np.zeros((1, 2)), ("a", "b"), ("c",)
        )


def test_evaluation_may_allow_a_novel_vector_equal_to_a_known_one(fitted, sim_split):
    existing = fitted.registry.known_attributes[4]
    model = fitted.add_novel_classes(["twin"], [existing], allow_known_vectors=True)
    assert model.registry.novel_names == ["twin"]
    with pytest.raises(DuplicateClassError, match="same attribute vector as existing class 'twin'"):
        model.add_novel_classes(["twin2"], [existing], allow_known_vectors=True)


def test_repeated_class_names_are_rejected():
    with pytest.raises(DatasetError, match="repeated: a"):
        TactileDataset(np.zeros((2, 4)), [0, 1], [0, 1], np.eye(2), ("x", "y"), ("a", "a"))
