"""The real BioTac pilot (../shared/data/biotac_pilot): every trial's phases, its layout
read and written back unchanged, and its tactile images."""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
import pytest

from app.data.biotac import load_biotac, read_biotac_h5, write_biotac_h5
from app.data.sources import load_dataset, open_dataset
from app.framework.tactile_image import TactileImageFeaturizer, featurize_dataset


@pytest.fixture(scope="module")
def pilot(biotac_pilot_path):
    return load_biotac(biotac_pilot_path)


def test_pilot_loads_with_labels_trial_ids_and_pressures(pilot):
    assert pilot.class_names == (
        "bouncy_foam",
        "cork",
        "glass_bottle",
        "hard_rough_foam",
        "metal_bar",
    )
    assert len(pilot) == 74 and pilot.attribute_names == ()
    assert Counter(pilot.labels.tolist()) == {0: 15, 1: 15, 2: 14, 3: 15, 4: 15}
    np.testing.assert_array_equal(pilot.trial_ids, np.arange(74))
    assert Counter(pilot.grip_pressure.tolist()) == {100.0: 25, 150.0: 24, 200.0: 25}
    assert "glass_bottle.h5/glass_bottle_pdc150_1cm_02" not in pilot.groups  # missing, per README
    assert pilot.groups[0] == "bouncy_foam.h5/bouncy_foam_pdc100_1cm_01"
    assert all(t.n_fingers == 2 and 4100 <= t.n_frames <= 11200 for t in pilot.trials)


def test_every_pilot_finger_shows_tap_hold_and_squeeze(pilot):
    """The README: a short tap (about frame 700), a hold (about 1,400 - 3,000) and a squeeze
    (about 3,700 - 4,200), found in pdc by the default rule in every finger of every trial."""
    for group, trial in zip(pilot.groups, pilot.trials, strict=True):
        for bounds in trial.phase_bounds():
            (tap, hold, squeeze) = bounds
            assert 550 <= tap[0] and tap[1] <= 850 and 5 <= tap[1] - tap[0] <= 60, group
            assert 950 <= hold[0] <= 1500 and 2700 <= hold[1] <= 3150, group
            assert 3400 <= squeeze[0] <= 3900 and 3800 <= squeeze[1] <= 4350, group


def test_pilot_file_written_back_reads_identical(biotac_pilot_path, tmp_path):
    trials = read_biotac_h5(biotac_pilot_path / "glass_bottle.h5")
    assert len(trials) == 14 and all(t.timestamps is not None for t in trials.values())
    write_biotac_h5(tmp_path / "glass_bottle.h5", trials)
    back = read_biotac_h5(tmp_path / "glass_bottle.h5")
    assert list(back) == list(trials)
    assert all(back[name].same_as(trial) for name, trial in trials.items())


def test_pilot_images_from_a_featurizer_fitted_on_training_trials(pilot):
    train = pilot.subset(pilot.trial_ids % 3 != 0)
    test = pilot.subset(pilot.trial_ids % 3 == 0)
    fz = TactileImageFeaturizer().fit(train.trials)
    ds = featurize_dataset(test, fz)
    assert ds.samples.shape == (2 * len(test), 24, 30) and np.isfinite(ds.samples).all()
    assert set(ds.trials.tolist()) == set(test.trial_ids.tolist())
    start = time.perf_counter()
    images = fz.transform(pilot.trials[0])
    assert images.shape == (2, 24, 30)
    assert time.perf_counter() - start < 1.0  # ~10 ms on one core


def test_pilot_by_spec(biotac_pilot_path):
    raw = open_dataset(f"biotac:{biotac_pilot_path}")
    assert len(raw) == 74
    ds = load_dataset(f"biotac:{biotac_pilot_path}")
    assert ds.name == "biotac" and ds.samples.shape == (148, 24, 30) and ds.n_attributes == 0
