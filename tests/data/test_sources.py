"""Dataset spec strings: every accepted form, and clear errors for the rest."""

from pathlib import Path

import numpy as np
import pytest

from app.data import sources
from app.data.simulator import simulate_dataset
from app.data.sources import DatasetSpecError, default_phac2_path, load_dataset

from .test_phac2 import write_fake_phac2


def test_simulated_default():
    ds = load_dataset("simulated")
    assert ds.name == "simulated" and ds.n_classes == 60 and ds.samples.shape == (600, 32, 30)
    np.testing.assert_array_equal(ds.samples, simulate_dataset(seed=0).samples)


def test_simulated_seed_is_passed_on():
    a, b = load_dataset("simulated:12", seed=1), load_dataset("simulated:12", seed=2)
    assert a.n_classes == b.n_classes == 12
    np.testing.assert_array_equal(a.samples, simulate_dataset(12, seed=1).samples)
    assert not np.allclose(a.samples, b.samples)


def test_phac2_with_explicit_path(tmp_path):
    root = write_fake_phac2(tmp_path / "fake")
    ds = load_dataset(f"phac2:{root}")
    assert ds.name == "phac2" and ds.object_ids == (101, 201, 301)


def test_phac2_default_path_prefers_environment(tmp_path, monkeypatch):
    root = write_fake_phac2(tmp_path / "fake")
    monkeypatch.setenv("TACTILE_PHAC2_PATH", str(root))
    assert default_phac2_path() == root
    assert load_dataset("phac2").object_ids == (101, 201, 301)


def test_phac2_default_path_skips_missing_candidates(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_PHAC2_PATH", str(tmp_path / "absent"))
    fallback = tmp_path / "repo" / ".." / "shared" / "data" / "phac2"
    write_fake_phac2(fallback)
    monkeypatch.setattr(sources, "_REPO_ROOT", tmp_path / "repo")
    assert default_phac2_path() == fallback
    monkeypatch.chdir(tmp_path / "repo")  # ./../shared/data/phac2 also resolves here
    monkeypatch.setattr(sources, "_REPO_ROOT", tmp_path / "elsewhere")
    assert default_phac2_path() == Path("..", "shared", "data", "phac2")


def test_phac2_missing_path_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent"):
        load_dataset(f"phac2:{tmp_path / 'absent'}")


@pytest.mark.phac2
def test_phac2_real_data_by_spec(phac2_path, monkeypatch):
    monkeypatch.delenv("TACTILE_PHAC2_PATH", raising=False)
    assert default_phac2_path().resolve() == phac2_path.resolve()
    for spec in ("phac2", f"phac2:{phac2_path}"):
        ds = load_dataset(spec)
        assert ds.samples.shape == (600, 188) and ds.n_attributes == 19


@pytest.mark.parametrize(
    "spec",
    ["", "sim", "simulated:", "simulated:0", "simulated:-3", "simulated:abc", "simulated:2.5",
     "simulated:²", "phac2:", "csv:/tmp/x", "SIMULATED"],
)  # fmt: skip
def test_bad_specs(spec):
    with pytest.raises(DatasetSpecError) as err:
        load_dataset(spec)
    assert isinstance(err.value, ValueError)
    for form in ("simulated", "simulated:N", "phac2:PATH"):
        assert form in str(err.value)
