"""Input health (``app.framework.input_health``): a profile fitted on training trials passes
held-out real trials and flags broken inputs (zeros, saturation, a scale off by orders of
magnitude, a dead channel) on the simulator, PHAC-2 and the BioTac pilot's raw trials; a
fitted model's answers carry it, its bundle keeps it, and a bundle without it answers
null; missing procedures are no outlier by themselves."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from app.data.biotac import load_biotac
from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.input_health import OUTLIER_THRESHOLD, InputProfile
from app.framework.registry import make_method
from bench.input_health import _broken, corrupt, held_out

BIOTAC = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "biotac_pilot"
BROKEN = ("zeros", "saturated", "scale_1e6", "scale_1e-6", "dead_zero", "dead_stuck")


def outliers(profile: InputProfile, x: np.ndarray) -> np.ndarray:
    return profile.score(x) > OUTLIER_THRESHOLD


@pytest.fixture(scope="module")
def simulated():
    return simulate_dataset(seed=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_simulator_held_out_trials_pass_and_broken_ones_are_flagged(simulated, seed):
    x, test = simulated.samples, held_out(simulated.trials, seed)
    profile = InputProfile.fit(x[~test])
    assert outliers(profile, x[test]).mean() <= 0.01
    top = float(np.abs(x[~test]).max())
    for kind in BROKEN:
        broken = corrupt(x[test], kind, top, np.random.default_rng(seed))
        assert outliers(profile, broken).all(), kind


def test_phac2_held_out_trials_pass_and_broken_ones_are_flagged(phac2_path):
    data = load_phac2(phac2_path)
    x, test = data.samples, held_out(data.trials, 0)
    profile = InputProfile.fit(x[~test])
    assert outliers(profile, x[test]).mean() <= 0.01
    top = float(np.abs(x[~test]).max())
    rng = np.random.default_rng(0)
    for kind in ("zeros", "saturated", "scale_1e6", "scale_1e-6"):
        assert outliers(profile, corrupt(x[test], kind, top, rng)).all(), kind
    # a flat sample's channel is one feature: at 0 it can show only where 0 is outside the
    # feature's training range (PHAC-2: about a third of them); it does on most of those,
    # all but the features whose training values reach down close to 0 (0.79 here)
    told = np.flatnonzero((profile.low > 0) | (profile.high < 0))
    assert len(told) > 30
    dead = np.repeat(x[test][:1], len(told), axis=0)
    dead[np.arange(len(told)), told] = 0.0
    assert outliers(profile, dead).mean() >= 0.7


def test_biotac_pilot_held_out_trials_pass_and_broken_fingers_are_flagged():
    if not BIOTAC.is_dir():
        pytest.skip(f"BioTac pilot not found at {BIOTAC.resolve()}")
    from app.framework.tactile_image import featurize_dataset

    data = load_biotac(BIOTAC)
    test = held_out(data.trial_ids, 0)
    train = data.subset(np.flatnonzero(~test))
    featurizer = make_method("best")._new_featurizer().fit(train.trials)
    profile = InputProfile.fit(featurize_dataset(train, featurizer, augment=True).samples)
    trials = [t for t, m in zip(data.trials, test, strict=True) if m]
    assert not outliers(profile, featurizer.transform(trials)).any()
    rng = np.random.default_rng(0)
    for kind in ("scale_1e6", "dead_zero", "dead_stuck", "zeros_but_pdc", "saturated_but_pdc"):
        for trial in trials[:4]:
            images = featurizer.transform([_broken(trial, kind, rng)])
            assert outliers(profile, images)[0], kind  # finger 0, the broken one
            assert not outliers(profile, images)[1], kind  # the other finger is sound


@pytest.fixture(scope="module")
def model(simulated):
    """``best`` on the simulator's first 8 trials of each object (quick parameters)."""
    train = simulated.subset(np.arange(len(simulated)) % 10 < 8)
    return make_method("best", n_estimators=40, tuning_rounds=1).fit(train)


def test_a_fitted_model_answers_with_its_input_health(model, simulated):
    held = simulated.samples[np.arange(len(simulated)) % 10 >= 8]
    batch = model.recognize_batch(held)
    assert batch.input_outlier.dtype == bool and batch.input_outlier_score.dtype == np.float64
    assert batch.input_outlier.mean() <= 0.01
    broken = model.recognize(np.zeros_like(held[:2]))
    assert [r.input_outlier for r in broken] == [True, True]
    assert broken[0].input_outlier_score > OUTLIER_THRESHOLD
    record = model.recognize_batch(held[:1] * 1e6).records()[0]
    assert record["input_outlier"] is True and record["input_outlier_score"] > 10
    assert np.allclose(model.input_outlier_score(held[:5]), batch.input_outlier_score[:5])


def test_a_group_is_an_outlier_when_any_of_its_samples_is(model, simulated):
    x = simulated.samples[:3].copy()
    x[1] *= 1e6
    batch = model.recognize_batch(x, groups=np.array([0, 0, 1]))
    assert batch.input_outlier.tolist() == [True, False]
    assert batch.input_outlier_score[0] == model.input_outlier_score(x[1:2])[0]


def test_missing_procedures_are_not_an_outlier_by_themselves(simulated):
    model = make_method("best", n_estimators=40, tuning_rounds=1, by_procedure=True).fit(
        simulated.subset(np.arange(len(simulated)) % 10 < 8)
    )
    assert model.answers_from_some_procedures
    held = simulated.samples[np.arange(len(simulated)) % 10 >= 8][:20].copy()
    rows = held.shape[1] // len(model.procedures)
    held[:, rows:] = np.nan  # only the first procedure done
    batch = model.recognize_batch(held)
    assert not batch.input_outlier.any()
    assert np.isfinite(batch.input_outlier_score).all()
    held[0, :rows] = 0.0  # the one procedure there is, dead
    assert model.recognize_batch(held[:1]).input_outlier[0]


def test_the_bundle_keeps_the_profile(model, simulated):
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    x = simulated.samples[:10] * np.float32(3.0)
    assert np.array_equal(
        loaded.recognize_batch(x).input_outlier_score, model.recognize_batch(x).input_outlier_score
    )


def rewritten(data: bytes, edit) -> bytes:
    """The bundle ``data`` with its manifest and arrays passed through ``edit``."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        manifest = json.loads(zf.read("manifest.json"))
        with np.load(io.BytesIO(zf.read("arrays.npz"))) as npz:
            arrays = {k: npz[k] for k in npz.files}
    edit(manifest, arrays)
    return bundle._zip(manifest, arrays)


def test_a_bundle_written_before_profiles_answers_null(model, simulated):
    def drop(manifest, arrays):
        del manifest["input_profile"]
        for name in [n for n in arrays if n.startswith("input_profile/")]:
            del arrays[name]

    old = bundle.from_bytes(rewritten(bundle.to_bytes(model), drop))
    assert old.input_profile_ is None
    answer = old.recognize(np.zeros_like(simulated.samples[:1]))[0]
    assert answer.input_outlier is None and answer.input_outlier_score is None
    record = old.recognize_batch(simulated.samples[:1]).records()[0]
    assert record["input_outlier"] is None and record["input_outlier_score"] is None
    # the same model's other answers are as before: without a profile nothing is an outlier,
    # so the old bundle names what the model guesses where it abstains on a dead sensor
    zeros = np.zeros_like(simulated.samples[:1])
    assert model.recognize(zeros)[0].kind == "input_outlier"
    assert answer.class_name == model.recognize(zeros, outliers="answer")[0].class_name


def test_a_damaged_profile_is_a_bundle_error(model):
    def shorten(manifest, arrays):
        arrays["input_profile/low"] = arrays["input_profile/low"][:3]

    with pytest.raises(BundleError, match="input profile"):
        bundle.from_bytes(rewritten(bundle.to_bytes(model), shorten))


def test_window_drift_names_the_dead_channel(simulated):
    x, test = simulated.samples, held_out(simulated.trials, 0)
    profile = InputProfile.fit(x[~test])
    mixed = profile.window_drift(profile.features(x[test]))
    assert mixed.shape == (32,) and mixed.max() < 1.0
    dead = x[test].copy()
    dead[:, 5] = dead[:, 5, :1]  # stuck at its first value
    drift = profile.window_drift(profile.features(dead))
    assert drift.argmax() == 5 and drift[5] > 10 and np.delete(drift, 5).max() < 1.0


def test_profile_state_round_trip_and_checks(simulated):
    profile = InputProfile.fit(simulated.samples)
    meta, arrays = profile.get_state()
    again = InputProfile.from_state(meta, arrays)
    x = simulated.samples[:7] * np.float32(1.5)
    assert np.array_equal(again.score(x), profile.score(x))
    with pytest.raises(ValueError, match="shape"):
        InputProfile.from_state(meta, {**arrays, "width": arrays["width"][:-1]})
    with pytest.raises(ValueError, match="version"):
        InputProfile.from_state({**meta, "version": 99}, arrays)
