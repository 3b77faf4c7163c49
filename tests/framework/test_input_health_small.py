"""A profile of few training samples sets its outlier threshold from its own samples, so a
service's first model (2 touches of each of a few objects) does not abstain on its objects'
next touches, while a zeroed or saturated sensor is still an outlier."""

from __future__ import annotations

import numpy as np

from app.data.simulator import simulate_dataset
from app.framework.input_health import CALIBRATE_BELOW, OUTLIER_THRESHOLD, InputProfile


def _first_touches(n_objects: int, per_object: int):
    ds = simulate_dataset(n_objects, 10, seed=8080)
    first = np.r_[[np.flatnonzero(ds.labels == k)[:per_object] for k in range(n_objects)]]
    first = first.ravel()
    rest = np.setdiff1d(np.arange(len(ds)), first)
    return ds.samples[first], ds.samples[rest]


def test_a_profile_of_six_touches_passes_its_objects_next_touches_and_flags_faults():
    train, later = _first_touches(3, 2)
    profile = InputProfile.fit(train)
    assert profile.threshold > OUTLIER_THRESHOLD  # the fixed one flagged most of them
    assert np.mean(InputProfile.fit(train).score(later) > OUTLIER_THRESHOLD) > 0.5
    assert np.mean(profile.is_outlier(profile.score(later))) <= 0.05
    assert profile.is_outlier(profile.score(np.zeros_like(later[:5]))).all()
    assert profile.is_outlier(profile.score(later[:5] * 1000)).all()


def test_a_profile_of_many_samples_keeps_the_chosen_threshold():
    train = simulate_dataset(30, 8, seed=1).samples
    assert len(train) >= CALIBRATE_BELOW
    assert InputProfile.fit(train).threshold == OUTLIER_THRESHOLD


def test_the_threshold_survives_the_state_and_old_states_read_the_fixed_one():
    profile = InputProfile.fit(_first_touches(3, 2)[0])
    meta, arrays = profile.get_state()
    again = InputProfile.from_state(meta, arrays)
    assert again.threshold == profile.threshold
    meta.pop("threshold")
    assert InputProfile.from_state(meta, arrays).threshold == OUTLIER_THRESHOLD
