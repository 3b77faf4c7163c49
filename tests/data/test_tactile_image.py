"""The tactile-image featurizer on synthetic signals whose image is known by construction."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.data.biotac import BioTacDataset, PhaseRule, RawTrial, RawTrialError
from app.framework.errors import NotFittedError
from app.framework.tactile_image import TactileImageFeaturizer, featurize_dataset, resample

from .biotac_samples import CONTACTS, REST, finger_data, synthetic_trial

PHASES = ((10, 40), (50, 110), (120, 135))  # 30, 60 and 15 frames: bins of 1, 2 and 0.5
N = 150


def linear_trial(seed: int = 0, n_fingers: int = 2, phases=PHASES) -> RawTrial:
    """pdc = 3 + 2k, tdc = 7, tac = -1, pac equal to its own time, and electrodes on a line:
    c + (k / 10 + 5 f) u for a unit vector u and finger f (rank one: PCA's first component
    is ±u)."""
    rng = np.random.default_rng(seed)
    k = np.arange(N, dtype=float)
    u = rng.normal(size=19)
    u /= np.linalg.norm(u)
    fingers = []
    for f in range(n_fingers):
        pac_times = k[:, None] - 0.5 + (np.arange(22) + 0.5) / 22
        fingers.append({
            "pdc": 3 + 2 * k + f, "tdc": np.full(N, 7.0), "tac": np.full(N, -1.0),
            "pac": pac_times, "electrodes": 3000 + np.outer(k / 10 + 5 * f, u),
        })  # fmt: skip
    return RawTrial(fingers=tuple(fingers), phases=phases)


def centres(s: int, e: int, offset: float = 0.5, n_steps: int = 30) -> np.ndarray:
    """The documented sample times of phase [s, e): s - 0.5 + (i + offset) (e - s) / n_steps."""
    return s - 0.5 + (np.arange(n_steps) + offset) * (e - s) / n_steps


def raw_featurizer(**kwargs) -> TactileImageFeaturizer:
    return TactileImageFeaturizer(baseline="none", normalize=False, **kwargs)


def test_image_rows_are_known_by_construction():
    trial = linear_trial()
    fz = raw_featurizer().fit([trial])
    images = fz.transform(trial)
    assert images.shape == (2, 24, 30) and images.dtype == np.float32
    assert fz.channel_names[:9] == (
        "tap/pdc", "tap/pac", "tap/tac", "tap/tdc", "tap/e0", "tap/e1", "tap/e2", "tap/e3",
        "hold/pdc",
    )  # fmt: skip
    for p, (s, e) in enumerate(PHASES):
        rows = images[0, 8 * p : 8 * p + 8]
        t = centres(s, e)
        np.testing.assert_allclose(rows[0], 3 + 2 * t, rtol=1e-6)  # linear pdc: its value at t
        np.testing.assert_allclose(rows[1], t, atol=1e-4)  # pac: flattened in time order
        np.testing.assert_allclose(rows[2], -1.0)  # constant tac
        np.testing.assert_allclose(rows[3], 7.0)  # constant tdc
    # a phase of exactly 30 frames gives the frames themselves
    np.testing.assert_allclose(images[0, 0], 3 + 2 * np.arange(10, 40), rtol=1e-6)


def test_electrode_components_follow_the_line():
    trial = linear_trial()
    fz = raw_featurizer().fit([trial])
    u = trial.fingers[0].electrodes[-1] - trial.fingers[0].electrodes[0]  # float32 counts
    u /= np.linalg.norm(u)
    sign = np.sign(fz.pca_components_[0] @ u)
    assert abs(fz.pca_components_[0] @ u) == pytest.approx(1.0, abs=1e-6)
    images = fz.transform(trial)
    t = np.concatenate([centres(s, e) for s, e in PHASES])
    pcs = np.stack([np.concatenate([images[f, 8 * p + 4] for p in range(3)]) for f in range(2)])
    expected = sign * (t / 10 + 5 * np.arange(2)[:, None])
    np.testing.assert_allclose(pcs - pcs.mean(), expected - expected.mean(), atol=1e-3)
    for f in range(2):
        for c in (5, 6, 7):  # the data are rank one: the other components do not vary
            assert np.ptp(np.concatenate([images[f, 8 * p + c] for p in range(3)])) < 1e-2


def test_offsets_shift_the_samples_and_augment_yields_every_finger_and_offset():
    trial = linear_trial()
    fz = raw_featurizer(n_offsets=5).fit([trial])
    np.testing.assert_allclose(fz.offsets, [0.1, 0.3, 0.5, 0.7, 0.9])
    for offset in fz.offsets:
        image = fz.transform(trial, offset=offset)[0]
        s, e = PHASES[1]
        np.testing.assert_allclose(image[8], 3 + 2 * centres(s, e, offset), rtol=1e-6)
    images, ids = fz.augment([trial, linear_trial(seed=1)], [7, 9])
    assert images.shape == (2 * 2 * 5, 24, 30)
    np.testing.assert_array_equal(ids, [7] * 10 + [9] * 10)
    np.testing.assert_allclose(images[4:6], fz.transform(trial, offset=0.5), rtol=1e-6)


def test_resample_box_filters_long_phases_and_interpolates_short_ones():
    t = np.arange(100.0)
    x = np.where(t % 2 == 0, 1.0, -1.0)  # alternating: a sampled point would alias it
    np.testing.assert_allclose(resample(x, t, 9.5, 69.5, 30), 0.0, atol=1e-12)
    y = 5 + 0.5 * t
    np.testing.assert_allclose(
        resample(y, t, 20.0, 23.0, 30), 5 + 0.5 * (20 + (np.arange(30) + 0.5) * 0.1)
    )
    two = np.column_stack([y, -y])
    np.testing.assert_allclose(
        resample(two, t, 0.0, 99.0, 30)[:, 1], -resample(y, t, 0.0, 99.0, 30)
    )


def test_phases_from_the_rule_and_baseline_subtraction():
    trial = synthetic_trial(seed=4)  # no phases given: found in pdc (tests/data/biotac_samples)
    fz = TactileImageFeaturizer(normalize=False).fit([trial])  # baseline "rest" by default
    assert fz.phases(trial) == (CONTACTS, CONTACTS)
    images = fz.transform(trial)
    for p in range(3):  # pdc in contact is rest + 200: 200 after the resting level goes
        np.testing.assert_allclose(images[:, 8 * p, 1:-1], 200.0)
    # the edge bins reach half a frame outside the contact, where pdc is interpolated from
    # rest (frame 149) to 200 (frame 150): the tap's first bin [149.5, 150.17] has mean
    # (0.5 * 100 ... 200 + 1/6 * 200) / (2/3) = 162.5 above rest
    np.testing.assert_allclose(images[:, 0, [0, -1]], 162.5)
    kept = raw_featurizer().fit([trial]).transform(trial)
    np.testing.assert_allclose(kept[:, 0, 1:-1], REST + 200.0)
    rest_tdc = np.median(trial.fingers[0].tdc[:100])
    np.testing.assert_allclose(images[0, 3], kept[0, 3] - rest_tdc, atol=1e-3)


def test_normalisation_uses_training_statistics_only():
    train = [synthetic_trial(seed=s) for s in range(3)]
    fz = TactileImageFeaturizer().fit(train)
    x = fz.transform(train)
    assert x.shape == (6, 24, 30)
    np.testing.assert_allclose(x.mean(axis=(0, 2)), 0.0, atol=1e-4)
    varying = x.std(axis=(0, 2)) > 0
    np.testing.assert_allclose(x.std(axis=(0, 2))[varying], 1.0, rtol=1e-4)
    other = synthetic_trial(seed=10, rise=400.0)
    raw = raw_featurizer().fit(train)
    expected = (raw.transform(other) - REST - fz.image_mean_[:, None]) / fz.image_scale_[:, None]
    pdc_rows = [0, 8, 16]
    np.testing.assert_allclose(fz.transform(other)[:, pdc_rows], expected[:, pdc_rows], rtol=1e-5)


def test_state_is_json_and_arrays_and_restores_the_same_images():
    train = [synthetic_trial(seed=s) for s in range(3)]
    fz = TactileImageFeaturizer(phase_rule=PhaseRule(min_gap=15)).fit(train)
    meta, arrays = fz.get_state()
    meta = json.loads(json.dumps(meta))
    assert set(arrays) == {"pca_mean", "pca_components", "image_mean", "image_scale"}
    assert all(isinstance(a, np.ndarray) and a.dtype == np.float64 for a in arrays.values())
    again = TactileImageFeaturizer.from_state(meta, arrays)
    assert again.get_params() == fz.get_params() and again.phase_rule.min_gap == 15
    other = synthetic_trial(seed=11)
    np.testing.assert_array_equal(again.transform(other), fz.transform(other))
    with pytest.raises(ValueError, match="lacks array 'image_scale'"):
        TactileImageFeaturizer.from_state(
            meta, {k: v for k, v in arrays.items() if k != "image_scale"}
        )
    with pytest.raises(ValueError, match=r"'pca_components' must be finite of shape \(4, 19\)"):
        TactileImageFeaturizer.from_state(meta, {**arrays, "pca_components": np.zeros((3, 19))})
    with pytest.raises(ValueError, match="not a tactile-image featurizer state"):
        TactileImageFeaturizer.from_state({**meta, "version": 99}, arrays)


def test_errors_name_the_trial_finger_and_channel():
    fz = TactileImageFeaturizer().fit([synthetic_trial()])
    flat = finger_data()
    flat["pdc"] = np.full(800, REST)
    with pytest.raises(RawTrialError, match="no contact") as err:
        fz.transform([synthetic_trial(), RawTrial(fingers=(finger_data(), flat))])
    assert (err.value.trial, err.value.finger, err.value.channel) == (1, 1, "pdc")
    two = RawTrial(fingers=(finger_data(),), phases=((150, 170), (300, 500)))
    with pytest.raises(RawTrialError, match="gives 2 phase") as err:
        fz.transform([two])
    assert (err.value.trial, err.value.channel) == (0, "phases")
    at_zero = RawTrial(fingers=(finger_data(),), phases=((0, 170), (300, 500), (600, 660)))
    with pytest.raises(RawTrialError, match="baseline 'rest' needs frames at rest") as err:
        fz.transform([at_zero])
    assert (err.value.trial, err.value.finger) == (0, 0)
    with pytest.raises(RawTrialError, match="missing channel") as err:
        fz.transform([{"fingers": [{"pdc": [1.0, 2.0]}]}])
    assert (err.value.trial, err.value.finger, err.value.channel) == (0, 0, "tdc")


def test_parameters_are_validated_and_unfitted_use_refused():
    with pytest.raises(ValueError, match="n_components must be an integer >= 1 and <= 19"):
        TactileImageFeaturizer(n_components=20)
    with pytest.raises(ValueError, match="baseline must be one of none, rest"):
        TactileImageFeaturizer(baseline="zero")
    with pytest.raises(ValueError, match="phase_rule finds 3 phases but phase_names names 4"):
        TactileImageFeaturizer(phase_names=("a", "b", "c", "d"), phase_rule=PhaseRule())
    with pytest.raises(NotFittedError):
        TactileImageFeaturizer().transform(synthetic_trial())
    four = TactileImageFeaturizer(phase_names=("squeeze", "hold", "slide", "move_down"))
    assert four.image_shape == (32, 30)  # PHAC-2's four procedures: the paper's 32 x 30


def test_featurize_dataset_keeps_labels_and_trial_ids():
    trials = tuple(synthetic_trial(seed=s) for s in range(4))
    raw = BioTacDataset(
        trials=trials, labels=[0, 1, 1, 0], trial_ids=[10, 11, 12, 13], class_names=("a", "b")
    )
    fz = TactileImageFeaturizer().fit(raw.subset([0, 1]).trials)
    ds = featurize_dataset(raw, fz)
    assert ds.samples.shape == (8, 24, 30) and ds.attribute_values.shape == (2, 0)
    np.testing.assert_array_equal(ds.trials, [10, 10, 11, 11, 12, 12, 13, 13])
    np.testing.assert_array_equal(ds.labels, [0, 0, 1, 1, 1, 1, 0, 0])
    aug = featurize_dataset(raw, fz, augment=True)
    assert len(aug) == 40 and np.bincount(aug.labels).tolist() == [20, 20]
