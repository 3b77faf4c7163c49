"""PHAC-2 loader: the real data (marked phac2) and malformed copies written to tmp_path."""

import csv
from pathlib import Path

import numpy as np
import pytest

from app.data.dataset import DatasetError
from app.data.phac2 import Phac2FormatError, feature_names, load_phac2
from app.data.simulator import PAPER_ATTRIBUTES

ADJECTIVES = ("hard", "soft", "rare", "common")


def write_fake_phac2(root: Path, **overrides) -> Path:
    """A tiny PHAC-2-shaped folder: 3 objects x 2 trials x (4 phases, 5 features)."""
    root.mkdir(parents=True, exist_ok=True)
    ids = np.repeat([301, 101, 201], 2)  # deliberately not sorted
    arrays = {
        "features": np.arange(6 * 4 * 5, dtype=np.float64).reshape(6, 4, 5) * 1e6,
        "object_id": ids,
        "trial": np.tile([1, 2], 3),
        "phases": np.array(["A", "B", "C", "D"]),
        "feature_names": np.array([f"f{i}" for i in range(5)]),
    }
    arrays.update(overrides)
    np.savez(
        root / "phac2_static_features.npz", **{k: v for k, v in arrays.items() if v is not None}
    )
    with (root / "objects.csv").open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["object_id", "name", *ADJECTIVES])
        out.writerows(
            [[301, "brick", 1, 0, 0, 1], [101, "sponge", 0, 1, 1, 1], [201, "foam", 0, 1, 0, 1]]
        )
    return root


# ---------------------------------------------------------------- synthetic folders


def test_fake_folder_loads_sorted_by_object_id(tmp_path):
    ds = load_phac2(write_fake_phac2(tmp_path), min_objects_per_attribute=1)
    assert ds.object_ids == (101, 201, 301)
    assert ds.class_names == ("sponge", "foam", "brick")
    assert ds.attribute_names == ADJECTIVES  # csv column order
    np.testing.assert_array_equal(ds.class_attributes, [[0, 1, 1, 1], [0, 1, 0, 1], [1, 0, 0, 1]])
    # Sample i keeps the npz row order; its label is the sorted position of its object.
    np.testing.assert_array_equal(ds.labels, [2, 2, 0, 0, 1, 1])
    assert ds.samples.shape == (6, 20) and ds.samples.dtype == np.float32
    raw = np.load(tmp_path / "phac2_static_features.npz")["features"]
    np.testing.assert_array_equal(ds.samples, raw.reshape(6, 20).astype(np.float32))  # unscaled


def test_threshold_drops_rare_adjectives(tmp_path):
    root = write_fake_phac2(tmp_path)
    assert load_phac2(root, min_objects_per_attribute=2).attribute_names == ("soft", "common")
    assert load_phac2(root).attribute_names == ("common",)
    with pytest.raises(DatasetError, match="no adjective"):
        load_phac2(root, min_objects_per_attribute=4)
    with pytest.raises(ValueError, match=">= 1"):
        load_phac2(root, min_objects_per_attribute=0)


def test_missing_folder_names_the_path(tmp_path):
    missing = tmp_path / "nowhere"
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_phac2(missing)


def test_missing_file_names_the_file(tmp_path):
    root = write_fake_phac2(tmp_path)
    (root / "objects.csv").unlink()
    with pytest.raises(FileNotFoundError, match="objects.csv"):
        load_phac2(root)


def test_corrupt_npz(tmp_path):
    root = write_fake_phac2(tmp_path)
    (root / "phac2_static_features.npz").write_bytes(b"PK\x03\x04 this is not a zip archive")
    with pytest.raises(Phac2FormatError, match="cannot read"):
        load_phac2(root)


def test_truncated_npz(tmp_path):
    root = write_fake_phac2(tmp_path)
    npz = root / "phac2_static_features.npz"
    npz.write_bytes(npz.read_bytes()[:200])
    with pytest.raises(Phac2FormatError):
        load_phac2(root)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"trial": None}, "lacks keys"),
        ({"features": np.zeros((6, 4, 4))}, "features must be"),
        ({"object_id": np.repeat([301, 101, 201], 3)}, "must both be"),
        ({"features": np.full((6, 4, 5), np.nan)}, "NaN"),
        ({"object_id": np.repeat([301, 101, 999], 2)}, "not in objects.csv"),
        ({"trial": np.ones(6, dtype=int)}, "occurs twice"),
    ],
)
def test_malformed_arrays(tmp_path, override, message):
    root = write_fake_phac2(tmp_path, **override)
    with pytest.raises(Phac2FormatError, match=message):
        load_phac2(root)


def test_malformed_csv(tmp_path):
    root = write_fake_phac2(tmp_path)
    (root / "objects.csv").write_text("object_id,name,hard\n101,sponge,maybe\n")
    with pytest.raises(Phac2FormatError, match="malformed row"):
        load_phac2(root)
    (root / "objects.csv").write_text("id,label,hard\n101,sponge,1\n")
    with pytest.raises(Phac2FormatError, match="must start with"):
        load_phac2(root)


# ---------------------------------------------------------------- the real data


@pytest.fixture(scope="module")
def phac2(phac2_path):
    return load_phac2(phac2_path)


@pytest.mark.phac2
def test_real_data_shape(phac2):
    assert phac2.name == "phac2"
    assert phac2.samples.shape == (600, 188) and phac2.samples.dtype == np.float32
    assert phac2.n_classes == 60
    np.testing.assert_array_equal(np.bincount(phac2.labels), np.full(60, 10))
    assert list(phac2.object_ids) == sorted(phac2.object_ids) and phac2.object_ids[0] == 101
    assert phac2.class_names[0] == "car_sponge_101"  # PHAC-2 has two car sponges


@pytest.mark.phac2
def test_real_data_has_the_papers_19_attributes(phac2):
    assert phac2.n_attributes == 19
    assert set(phac2.attribute_names) == set(PAPER_ATTRIBUTES)
    assert phac2.class_attributes.shape == (60, 19)
    assert phac2.class_attributes.sum(axis=0).min() >= 3


@pytest.mark.phac2
@pytest.mark.parametrize(("threshold", "expected"), [(1, 24), (2, 21), (3, 19), (4, 17)])
def test_real_data_threshold(phac2_path, threshold, expected):
    ds = load_phac2(phac2_path, min_objects_per_attribute=threshold)
    assert ds.n_attributes == expected
    assert ds.class_attributes.sum(axis=0).min() >= threshold


@pytest.mark.phac2
def test_real_data_trials_unique_per_object_and_trial(phac2, phac2_path):
    raw = np.load(phac2_path / "phac2_static_features.npz")
    np.testing.assert_array_equal(np.array(phac2.object_ids)[phac2.labels], raw["object_id"])
    pairs = list(zip(raw["object_id"].tolist(), raw["trial"].tolist(), strict=True))
    # (object, trial) -> trial id is one-to-one: 600 distinct pairs, 600 distinct ids.
    mapping = dict(zip(pairs, phac2.trials.tolist(), strict=True))
    assert len(mapping) == 600 and len(set(mapping.values())) == 600


@pytest.mark.phac2
def test_real_data_feature_names(phac2_path):
    names = feature_names(phac2_path)
    assert len(names) == 188
    assert names[0] == "SQUEEZE_SET_PRESSURE_SLOW/pdc_rise_count_f0"
    assert names[-1].startswith("MOVE_DOWN_5CM/electrode_pc3")


@pytest.mark.phac2
def test_class_names_are_unique_even_where_phac2_repeats_a_name(phac2_path):
    ds = load_phac2(phac2_path)
    assert len(set(ds.class_names)) == 60
    assert {"chalkboard_eraser_406", "chalkboard_eraser_408"} <= set(ds.class_names)
