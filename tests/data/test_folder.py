"""The folder: and biotac: file formats: round trips, and errors that name the file, the
row or group and the field."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.biotac import BioTacDataset, load_biotac, write_biotac_folder
from app.data.dataset import DatasetFileError, TactileDataset
from app.data.folder import load_folder, read_objects_csv, write_folder
from app.data.simulator import simulate_dataset
from app.data.sources import load_dataset, open_dataset

from .biotac_samples import synthetic_trial


def assert_same(a: TactileDataset, b: TactileDataset) -> None:
    np.testing.assert_array_equal(a.samples, b.samples)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.trials, b.trials)
    np.testing.assert_array_equal(a.attribute_values, b.attribute_values)  # NaN == NaN here
    assert a.attribute_names == b.attribute_names
    assert a.class_names == b.class_names and a.object_ids == b.object_ids


def graded_dataset() -> TactileDataset:
    values = np.array([[1, 0, 0.25], [np.nan, 1, 0.1], [0, 0.7, np.nan]], np.float32)
    rng = np.random.default_rng(0)
    return TactileDataset(
        samples=rng.normal(size=(6, 4, 5)), labels=[0, 0, 1, 1, 2, 2], trials=[5, 5, 9, 9, 2, 3],
        class_attributes=values, attribute_names=("hard", "soft", "rough"),
        class_names=("brick", "sponge, wet", "felt"), object_ids=(301, 101, 201))  # fmt: skip


def test_simulated_round_trip(tmp_path):
    ds = simulate_dataset(n_objects=6, seed=2)
    write_folder(ds, tmp_path)
    back = load_dataset(f"folder:{tmp_path}")
    assert_same(ds, back)
    assert back.name == "folder" and back.binary_attributes
    np.testing.assert_array_equal(back.class_attributes, ds.class_attributes)


def test_graded_not_known_values_object_ids_and_quoted_names_round_trip(tmp_path):
    ds = graded_dataset()
    write_folder(ds, tmp_path)
    assert (tmp_path / "objects.csv").read_text().splitlines()[:3] == [
        "object_id,name,hard,soft,rough", "301,brick,1,0,0.25", '101,"sponge, wet",,1,0.1',
    ]  # fmt: skip
    assert_same(ds, load_folder(tmp_path))


def test_no_attribute_columns_round_trip(tmp_path):
    ds = simulate_dataset(n_objects=3, seed=0)
    bare = TactileDataset(ds.samples, ds.labels, ds.trials, np.zeros((3, 0)), (), ds.class_names)
    write_folder(bare, tmp_path)
    assert (tmp_path / "objects.csv").read_text().splitlines()[0] == "name"
    back = load_folder(tmp_path)
    assert_same(bare, back) and back.n_attributes == 0


def test_existing_files_are_kept_unless_overwritten(tmp_path):
    ds = simulate_dataset(n_objects=3, seed=0)
    write_folder(ds, tmp_path)
    with pytest.raises(FileExistsError, match="already holds objects.csv, samples.npy"):
        write_folder(ds, tmp_path)
    write_folder(ds.subset(np.arange(10)), tmp_path, overwrite=True)
    assert len(load_folder(tmp_path)) == 10


def test_trials_numbered_per_object_are_pairs_of_object_and_trial(tmp_path):
    ds = simulate_dataset(n_objects=3, trials_per_object=4, seed=0)
    write_folder(ds, tmp_path)
    lines = (tmp_path / "samples.csv").read_text().splitlines()
    per_object = [lines[0]]
    seen: dict[str, int] = {}
    for line in lines[1:]:  # trial 1, 2, ... of every object, as PHAC-2 numbers them
        name = line.rsplit(",", 1)[0]
        seen[name] = seen.get(name, 0) + 1
        per_object.append(f"{name},{seen[name]}")
    (tmp_path / "samples.csv").write_text("\n".join(per_object) + "\n")
    back = load_folder(tmp_path)
    assert len(np.unique(back.trials)) == 12  # 3 objects x 4 trials, none merged
    for t in np.unique(back.trials):
        assert len(np.unique(back.labels[back.trials == t])) == 1
    # the same grouping as the original ids
    pairs = {(int(a), int(b)) for a, b in zip(ds.trials, back.trials, strict=True)}
    assert len(pairs) == 12


# ----------------------------------------------------------------- folder: errors
def write_good(root) -> None:
    write_folder(graded_dataset(), root)


def edit(path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


FOLDER_ERRORS = [
    # (file, how to break it, row, field, words in the message)
    ("objects.csv", lambda p: edit(p, "301,brick,1,0,0.25", "301,brick,1,yes,0.25"), 2, "soft",
     "'yes' is not a value in [0, 1]"),
    ("objects.csv", lambda p: edit(p, "301,brick,1,0,0.25", "301,brick,1,0,1.5"), 2, "rough",
     "'1.5' is not a value in [0, 1]"),
    ("objects.csv", lambda p: edit(p, "201,felt", "201,brick"), 4, "name",
     "object 'brick' is repeated (first at row 2)"),
    ("objects.csv", lambda p: edit(p, "301,brick,1,0,0.25", "301,brick,1,0"), 2, None,
     "has 4 cells where the header has 5"),
    ("objects.csv", lambda p: edit(p, "object_id,name", "id,name"), 1, "id",
     "the header must start with 'name'"),
    ("objects.csv", lambda p: edit(p, "hard,soft", "hard,hard"), 1, "hard", "repeated column name"),
    ("objects.csv", lambda p: edit(p, "201,felt", "x,felt"), 4, "object_id",
     "'x' is not an integer"),
    ("samples.csv", lambda p: edit(p, "felt,2", "velvet,2"), 6, "object",
     "object 'velvet' is not in objects.csv"),
    ("samples.csv", lambda p: edit(p, "felt,2", "felt,two"), 6, "trial",
     "trial 'two' is not an integer"),
    ("samples.csv", lambda p: edit(p, "object,trial", "name,trial"), 1, None,
     "the header must be 'object,trial'"),
    ("samples.csv", lambda p: edit(p, "felt,3\n", ""), None, None,
     "has 5 sample rows where samples.npy has 6 samples"),
    ("samples.npy",
     lambda p: np.save(p, np.where(np.arange(6)[:, None, None] == 4, np.nan, 1.0)
                       * np.ones((6, 4, 5))),
     4, None, "sample 4 (line 6 of samples.csv) contains NaN or infinity"),
    ("samples.npy", lambda p: np.save(p, np.array(["a"] * 6)), None, None, "must hold numbers"),
    ("samples.npy", lambda p: p.write_bytes(b"garbage"), None, None, "not a readable .npy array"),
    ("samples.npy", lambda p: p.unlink(), None, None, "file not found"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "breaks", "row", "field", "words"), FOLDER_ERRORS)
def test_folder_errors_name_file_row_and_field(tmp_path, name, breaks, row, field, words):
    write_good(tmp_path)
    breaks(tmp_path / name)
    with pytest.raises(DatasetFileError) as err:
        load_folder(tmp_path)
    e = err.value
    assert (e.file, e.row, e.field) == (str(tmp_path / name), row, field)
    assert str(e).startswith(str(tmp_path / name)) and words in str(e)
    if row is not None:
        assert f"row {row}" in str(e)
    if field is not None:
        assert f"field {field!r}" in str(e)


def test_objects_csv_may_omit_object_ids_and_attributes(tmp_path):
    (tmp_path / "objects.csv").write_text("\ufeffname\ncork\n\nmetal bar\n")  # BOM, blank line
    table = read_objects_csv(tmp_path / "objects.csv")
    assert table.names == ("cork", "metal bar") and table.values.shape == (2, 0)
    assert table.object_ids is None


# ----------------------------------------------------------------- biotac: folders
def small_biotac(with_attributes: bool = True) -> BioTacDataset:
    trials = tuple(synthetic_trial(seed=s) for s in range(6))
    return BioTacDataset(
        trials=trials, labels=[0, 0, 0, 1, 1, 1], trial_ids=range(6), class_names=("cork", "foam"),
        attribute_names=("hard", "squishy") if with_attributes else (),
        attribute_values=np.array([[1, 0.2], [np.nan, 1]]) if with_attributes else np.zeros((2, 0)),
        groups=("cork.h5/cork_pdc100_1cm_01", "cork.h5/cork_pdc150_1cm_01", "cork.h5/cork_x",
                "foam.h5/foam_pdc100_1cm_01", "foam.h5/foam_pdc100_1cm_02",
                "foam.h5/foam_pdc200_1cm_01"),
    )  # fmt: skip


def test_biotac_folder_write_then_load_is_identical(tmp_path):
    raw = small_biotac()
    write_biotac_folder(raw, tmp_path)
    back = load_biotac(tmp_path)
    assert back.class_names == raw.class_names and back.groups == raw.groups
    assert back.attribute_names == raw.attribute_names
    np.testing.assert_array_equal(back.attribute_values, raw.attribute_values.astype(np.float32))
    np.testing.assert_array_equal(back.labels, raw.labels)
    np.testing.assert_array_equal(back.trial_ids, np.arange(6))
    np.testing.assert_array_equal(back.grip_pressure, [100, 150, np.nan, 100, 100, 200])
    assert all(a.same_as(b) for a, b in zip(back.trials, raw.trials, strict=True))
    assert isinstance(open_dataset(f"biotac:{tmp_path}"), BioTacDataset)
    images = load_dataset(f"biotac:{tmp_path}")
    assert images.samples.shape == (12, 24, 30) and not images.binary_attributes


def test_biotac_objects_csv_must_match_the_files(tmp_path):
    write_biotac_folder(small_biotac(), tmp_path)
    (tmp_path / "objects.csv").write_text("name,hard\ncork,1\nfoam,0\nglass,1\n")
    with pytest.raises(DatasetFileError, match="row 4, field 'name': object 'glass' has no file"):
        load_biotac(tmp_path)
    (tmp_path / "objects.csv").write_text("name,hard\ncork,1\n")
    with pytest.raises(DatasetFileError, match="field 'name': has no row for object 'foam'"):
        load_biotac(tmp_path)


def test_biotac_folder_without_files(tmp_path):
    with pytest.raises(DatasetFileError, match="no HDF5 file"):
        load_biotac(tmp_path)
    with pytest.raises(FileNotFoundError, match="BioTac data folder not found"):
        load_biotac(tmp_path / "absent")
