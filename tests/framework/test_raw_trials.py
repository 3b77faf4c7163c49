"""Recognizers fitted on raw BioTac trials: the featurizer they keep and store, one answer
per trial from its fingers (groups fusion), the input-kind errors, and real pilot trials."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from app.data.biotac import RawTrial, RawTrialError, load_biotac
from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.errors import (
    BundleError,
    FrameworkError,
    InputKindError,
    InputShapeError,
    TrialInputError,
)
from app.framework.recognizer import RAW_TRIALS, SAMPLES, check_groups
from app.framework.registry import make_method
from app.framework.tactile_image import TactileImageFeaturizer

from .conftest import QUICK
from .raw_data import pilot_path, synthetic_biotac

FAST_BEST = dict(n_estimators=30, tuning_rounds=1)


@pytest.fixture(scope="module")
def raw():
    return synthetic_biotac(n_objects=3, trials_per_object=6)


@pytest.fixture(scope="module")
def train(raw):
    return raw.subset(raw.trial_ids % 6 != 0)


@pytest.fixture(scope="module")
def test_trials(raw):
    return raw.subset(raw.trial_ids % 6 == 0)


@pytest.fixture(scope="module")
def best_raw(train):
    return make_method("best", **FAST_BEST).fit(train)


@pytest.fixture(scope="module")
def samples_model():
    ds = simulate_dataset(n_objects=6, trials_per_object=4, seed=2)
    return make_method("best", **FAST_BEST).fit(ds)


# ----------------------------------------------------------------------------- fitting
def test_a_model_fitted_on_raw_trials_keeps_the_featurizer_fitted_on_them(best_raw, train):
    assert best_raw.input_kind == RAW_TRIALS
    fz = best_raw.featurizer
    assert isinstance(fz, TactileImageFeaturizer) and fz.is_fitted
    assert best_raw.input_shape == fz.image_shape == (24, 30)
    # fitted on exactly the training trials: a featurizer fitted on them has its arrays
    again = TactileImageFeaturizer().fit(train.trials)
    np.testing.assert_array_equal(again.image_mean_, fz.image_mean_)
    np.testing.assert_array_equal(again.pca_components_, fz.pca_components_)
    # best's default: every finger of every trial once (no sub-sampling augmentation)
    assert best_raw.featurizer.n_offsets == 1
    assert best_raw.metrics["n_train_samples"] == len(train) * 2


def test_featurizer_params_set_the_featurizer_and_are_checked(train):
    three = make_method("best", featurizer_params={"n_offsets": 3}, **FAST_BEST).fit(train)
    assert three.metrics["n_train_samples"] == len(train) * 2 * 3  # 3 offsets per finger
    assert three.featurizer.n_offsets == 3 and three.get_params()["featurizer_params"] == {
        "n_offsets": 3
    }
    # the paper's pipeline keeps the featurizer's default: the paper's 5 offsets
    paper = make_method("paper", **dict(QUICK, encoder_epochs=2)).fit(train)
    assert paper.featurizer.n_offsets == 5
    assert paper.metrics["n_train_samples"] == len(train) * 2 * 5
    with pytest.raises(FrameworkError, match="unknown option.*'offsets'"):
        make_method("best", featurizer_params={"offsets": 1}).fit(train)
    with pytest.raises(FrameworkError, match="n_steps must be an integer"):
        make_method("extratrees", featurizer_params={"n_steps": 0}).fit(train)
    with pytest.raises(FrameworkError, match="PhaseRule"):
        make_method("best", featurizer_params={"phase_rule": {"n_phases": 3, "bogus": 1}}).fit(
            train
        )


def test_a_model_of_samples_has_no_featurizer(samples_model):
    assert samples_model.featurizer is None and samples_model.input_kind == SAMPLES


# --------------------------------------------------------------------------- trials in
def test_trial_samples_give_one_image_per_finger_with_its_trial(best_raw, test_trials):
    trials = list(test_trials.trials)
    images, index = best_raw.trial_samples(trials)
    assert images.shape == (2 * len(trials), 24, 30) and images.dtype == np.float32
    np.testing.assert_array_equal(index, np.repeat(np.arange(len(trials)), 2))
    np.testing.assert_array_equal(images, best_raw.featurizer.transform(trials))
    # one trial alone, as a RawTrial or in its JSON form: its two fingers
    one, idx = best_raw.trial_samples(trials[1].to_dict())
    np.testing.assert_array_equal(one, images[2:4])
    np.testing.assert_array_equal(idx, [0, 0])


def test_recognize_trials_answers_each_trial_from_both_fingers(best_raw, test_trials):
    trials = list(test_trials.trials)
    answers = best_raw.recognize_trials(trials, top_k=2)
    assert len(answers) == len(trials)
    assert answers.top_index.shape == (len(trials), 2)
    assert [a.class_name for a in answers.answers()] == ["obj0", "obj1", "obj2"]
    images, index = best_raw.trial_samples(trials)
    fused = best_raw.recognize_batch(images, top_k=2, groups=index)
    np.testing.assert_array_equal(fused.top_index, answers.top_index)
    np.testing.assert_array_equal(fused.top_probability, answers.top_probability)


def test_attribute_proba_trials_is_the_mean_over_fingers():
    attrs = np.array([[1, 0], [0, 1], [1, 1]], np.float32)
    raw = synthetic_biotac(attributes=attrs)
    model = make_method("best", **FAST_BEST).fit(raw.subset(raw.trial_ids % 6 != 0))
    trials = list(raw.subset(raw.trial_ids % 6 == 0).trials)
    per_trial = model.attribute_proba_trials(trials)
    images, _ = model.trial_samples(trials)
    per_image = model.attribute_proba(images)
    assert per_trial.shape == (3, 2)
    np.testing.assert_allclose(per_trial, (per_image[0::2] + per_image[1::2]) / 2)


def test_a_raw_trial_enrols_one_shot_with_both_fingers():
    attrs = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]], np.float32)
    raw = synthetic_biotac(n_objects=4, attributes=attrs)
    model = make_method("best", **FAST_BEST).fit(
        _relabel(raw, raw.labels < 3, raw.trial_ids % 6 != 0)
    )
    zsl = model.add_novel_classes(["obj3"], attrs[3:])
    trial = raw.trials[int(np.flatnonzero(raw.labels == 3)[0])]
    osl = zsl.add_one_shot("obj3", zsl.trial_samples([trial])[0])
    assert osl.registry.novel_samples["obj3"].shape == (2, 24, 30)
    again = bundle.from_bytes(bundle.to_bytes(osl))
    np.testing.assert_array_equal(
        again.registry.novel_samples["obj3"], osl.trial_samples([trial])[0]
    )


def _relabel(raw, keep_classes, keep_trials):
    """The trials of the classes in ``keep_classes`` (a trial mask) and ``keep_trials``,
    with only those classes."""
    from app.data.biotac import BioTacDataset

    sub = raw.subset(keep_classes & keep_trials)
    classes = np.unique(sub.labels)
    remap = {int(c): i for i, c in enumerate(classes)}
    return BioTacDataset(
        trials=sub.trials,
        labels=np.array([remap[int(c)] for c in sub.labels]),
        trial_ids=sub.trial_ids,
        class_names=tuple(sub.class_names[c] for c in classes),
        attribute_names=sub.attribute_names,
        attribute_values=sub.attribute_values[classes],
        groups=sub.groups,
        grip_pressure=sub.grip_pressure,
    )


# ------------------------------------------------------------------------------ groups
def test_a_group_of_one_sample_is_the_plain_answer(samples_model):
    x = simulate_dataset(n_objects=6, trials_per_object=4, seed=5).samples[:7]
    plain = samples_model.recognize_batch(x, top_k=3)
    grouped = samples_model.recognize_batch(x, top_k=3, groups=np.arange(7)[::-1].copy())
    for name in ("top_index", "top_probability", "is_novel", "novelty_score"):
        np.testing.assert_array_equal(getattr(grouped, name), getattr(plain, name)[::-1])


def test_a_group_answer_is_the_mean_of_its_samples_evidence(samples_model):
    x = simulate_dataset(n_objects=6, trials_per_object=4, seed=5).samples[:6]
    groups = np.array([1, 0, 1, 2, 0, 1])
    fused = samples_model.recognize_batch(x, top_k=6, groups=groups)
    assert len(fused) == 3
    known = samples_model.known_proba(x)
    scores = samples_model.novelty_score(x)
    for g in range(3):
        mean_p = known[groups == g].mean(axis=0)
        order = np.argsort(-mean_p, kind="stable")  # equal values: the lower index first
        np.testing.assert_array_equal(fused.top_index[g], order)
        np.testing.assert_allclose(fused.top_probability[g], mean_p[order], rtol=1e-12)
        assert fused.novelty_score[g] == pytest.approx(scores[groups == g].mean(), rel=1e-12)
        assert fused.is_novel[g] == (fused.novelty_score[g] > samples_model.novelty_threshold)


def test_groups_fuse_novel_class_probabilities_too(samples_model):
    ds = simulate_dataset(n_objects=6, trials_per_object=4, seed=2)
    model = samples_model.add_novel_classes(["n1", "n2"], [[1] + [0] * 18, [0, 1] + [0] * 17])
    x = ds.samples[:4]
    groups = np.array([0, 0, 1, 1])
    novel = model.novel_proba(x)
    model.novelty_threshold = -np.inf  # route every group to the novel classes
    fused = model.recognize_batch(x, top_k=2, groups=groups)
    for g in range(2):
        mean_p = novel[groups == g].mean(axis=0)
        np.testing.assert_allclose(np.sort(fused.top_probability[g])[::-1], np.sort(mean_p)[::-1])
        assert set(fused.top_index[g]) == {6, 7}  # after the 6 known classes


@pytest.mark.parametrize(
    "groups, message",
    [
        ([0, 1], "one entry per sample"),
        ([0, 2, 2], "group 1 has no sample"),
        ([0, -1, 1], "0 … G-1"),
        ([0.5, 1, 0], "must be integers"),
        (["a", "b", "c"], "must be integers"),
    ],
)
def test_bad_groups_are_refused(samples_model, groups, message):
    x = simulate_dataset(n_objects=6, trials_per_object=4, seed=5).samples[:3]
    with pytest.raises(InputShapeError, match=message):
        samples_model.recognize_batch(x, groups=np.asarray(groups))


def test_check_groups_takes_whole_floats():
    np.testing.assert_array_equal(check_groups(np.array([0.0, 1.0, 0.0]), 3), [0, 1, 0])


# ------------------------------------------------------------------------- input kinds
def test_raw_trials_to_a_model_of_samples_raise_input_kind_error(samples_model, test_trials):
    trial = test_trials.trials[0]
    for call in (
        lambda: samples_model.trial_samples([trial]),
        lambda: samples_model.recognize_trials([trial]),
        lambda: samples_model.attribute_proba_trials([trial]),
        lambda: samples_model.recognize_batch([trial]),
        lambda: samples_model.recognize_batch(trial.to_dict()),
    ):
        with pytest.raises(
            InputKindError, match=r"takes fixed-shape samples of shape \(N, 32, 30\)"
        ):
            call()


def test_samples_to_a_raw_trial_model_raise_input_kind_error(best_raw, test_trials):
    sim = simulate_dataset(n_objects=6, trials_per_object=4, seed=5).samples[:2]  # (32, 30)
    with pytest.raises(InputKindError, match="fitted on raw BioTac trials") as info:
        best_raw.recognize_batch(sim)
    assert "got samples of shape (2, 32, 30)" in str(info.value)
    assert isinstance(info.value, InputShapeError)  # the service answers 422 for both
    with pytest.raises(InputKindError, match="use recognize_trials"):
        best_raw.recognize_batch(list(test_trials.trials))
    with pytest.raises(InputKindError, match="fitted on raw BioTac trials"):
        best_raw.add_novel_classes_from_samples({"new": sim})
    # its own images are its samples
    images, _ = best_raw.trial_samples(list(test_trials.trials))
    assert len(best_raw.recognize_batch(images)) == len(images)


def test_a_malformed_trial_names_trial_finger_and_channel(best_raw, test_trials):
    good = test_trials.trials[0].to_dict()
    bad = json.loads(json.dumps(good))
    del bad["fingers"][1]["pac"]
    with pytest.raises(TrialInputError, match="trial 1, finger 1, channel 'pac': missing") as info:
        best_raw.recognize_trials([good, bad])
    err = info.value
    assert (err.trial, err.finger, err.channel) == (1, 1, "pac")
    assert err.field == "trials[1].fingers[1].pac"
    flat = json.loads(json.dumps(good))
    flat["fingers"][0]["pdc"] = [800.0] * len(flat["fingers"][0]["pdc"])  # never touches
    with pytest.raises(TrialInputError, match="no contact") as info:
        best_raw.trial_samples([flat])
    assert (info.value.trial, info.value.finger, info.value.channel) == (0, 0, "pdc")
    with pytest.raises(InputShapeError, match="at least one trial"):
        best_raw.trial_samples([])


# ------------------------------------------------------------------------------ bundles
@pytest.mark.parametrize("method", ["best", "paper"])
def test_a_raw_trial_model_round_trips_through_its_bundle(method, train, test_trials, tmp_path):
    params = FAST_BEST if method == "best" else dict(QUICK, encoder_epochs=5)
    model = make_method(method, **params).fit(train)
    path = tmp_path / "raw.bundle"
    bundle.save(model, path)
    loaded = bundle.load(path)
    assert loaded.input_kind == RAW_TRIALS
    # a build that predates featurizers refuses the file instead of serving it as samples
    # (a later format version, a forest's records, implies them)
    with zipfile.ZipFile(path) as zf:
        manifest = json.loads(zf.read("manifest.json"))
    assert manifest["format_version"] >= bundle.RAW_TRIALS_FORMAT_VERSION
    meta, arrays = model.featurizer.get_state()
    meta2, arrays2 = loaded.featurizer.get_state()
    assert meta2 == meta
    for name, value in arrays.items():
        np.testing.assert_array_equal(arrays2[name], value)
    trials = list(test_trials.trials)
    before, after = model.recognize_trials(trials), loaded.recognize_trials(trials)
    for name in ("top_index", "top_probability", "is_novel"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name))
    # the paper's GMM scores agree to float rounding after loading (as tests/framework/
    # test_bundle.py has it for every paper model); best's are bit-identical
    rtol = 0 if method == "best" else 1e-6
    np.testing.assert_allclose(after.novelty_score, before.novelty_score, rtol=rtol)
    with zipfile.ZipFile(path) as zf:
        manifest = json.loads(zf.read("manifest.json"))
        with np.load(io.BytesIO(zf.read("arrays.npz"))) as npz:
            names = set(npz.files)
    assert manifest["featurizer"]["kind"] == "tactile-image"
    assert manifest["input_shape"] == [24, 30]
    assert {f"featurizer/{n}" for n in arrays} <= names
    # the store's split form carries it too
    head, parts = bundle.split(model)
    again = bundle.from_bytes(head, part=lambda sha: bundle.decode_part(parts[sha]))
    np.testing.assert_array_equal(again.recognize_trials(trials).top_index, before.top_index)


def test_a_bundle_without_featurizer_or_its_parameter_loads_as_before(samples_model):
    data = bundle.to_bytes(samples_model)
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        manifest = json.loads(zf.read("manifest.json"))
        npz = zf.read("arrays.npz")
    assert "featurizer" not in manifest
    del manifest["method_state"]["params"]["featurizer_params"]  # as bundles written before
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("manifest.json", json.dumps(manifest))
        zf.writestr("arrays.npz", npz)
    loaded = bundle.from_bytes(out.getvalue())
    assert loaded.featurizer is None and loaded.input_kind == SAMPLES
    assert loaded.featurizer_params is None
    x = simulate_dataset(n_objects=6, trials_per_object=4, seed=5).samples[:4]
    np.testing.assert_array_equal(loaded.known_proba(x), samples_model.known_proba(x))


def _rewrite(data: bytes, manifest_change=None, drop_arrays=()) -> bytes:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        manifest = json.loads(zf.read("manifest.json"))
        with np.load(io.BytesIO(zf.read("arrays.npz"))) as npz:
            arrays = {k: npz[k] for k in npz.files if k not in drop_arrays}
    if manifest_change:
        manifest_change(manifest)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("manifest.json", json.dumps(manifest))
        zf.writestr("arrays.npz", buf.getvalue())
    return out.getvalue()


def test_a_damaged_featurizer_in_a_bundle_fails_clearly(best_raw):
    data = bundle.to_bytes(best_raw)
    with pytest.raises(BundleError, match="featurizer is unreadable.*image_scale"):
        bundle.from_bytes(_rewrite(data, drop_arrays=("featurizer/image_scale",)))

    def other_steps(m):
        m["featurizer"]["n_steps"] = 20

    with pytest.raises(BundleError, match="featurizer"):
        bundle.from_bytes(_rewrite(data, other_steps))

    def no_entry(m):
        del m["featurizer"]

    with pytest.raises(BundleError, match="featurizer arrays but no featurizer entry"):
        bundle.from_bytes(_rewrite(data, no_entry))


# ------------------------------------------------------------------- the real pilot
def test_held_out_pilot_trials_are_recognised_one_answer_per_trial():
    pilot = load_biotac(pilot_path())
    held = pilot.trial_ids % 5 == 0  # 15 trials, every object among them
    model = make_method("best").fit(pilot.subset(~held))
    test = pilot.subset(held)
    answers = model.recognize_trials(list(test.trials))
    assert len(answers) == len(test) == 15
    names = np.array(model.registry.known_names)[answers.top_index[:, 0]]
    truth = np.array(pilot.class_names)[test.labels]
    assert np.mean(names == truth) >= 0.85, list(zip(names, truth, strict=True))
    # the same answers after the model's bundle round trip
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    np.testing.assert_array_equal(
        loaded.recognize_trials(list(test.trials)).top_probability, answers.top_probability
    )


def _without(trial: RawTrial, *missing: int) -> RawTrial:
    bounds = trial.phase_bounds()[0]
    phases = tuple(None if j in missing else b for j, b in enumerate(bounds))
    return RawTrial(fingers=trial.fingers, phases=phases)


def test_a_trial_lacking_a_phase_is_answered_from_the_others(best_raw, test_trials):
    whole = list(test_trials.trials)
    partial = [_without(t, 1) for t in whole]  # no hold
    images, _ = best_raw.trial_samples(partial)
    rows = best_raw.featurizer_.image_shape[0] // 3
    assert np.isnan(images[:, rows : 2 * rows]).all()  # the hold's block: missing
    assert np.isfinite(images[:, :rows]).all() and np.isfinite(images[:, 2 * rows :]).all()
    full, _ = best_raw.trial_samples(whole)  # the phases done: as in the whole trial
    np.testing.assert_array_equal(images[:, :rows], full[:, :rows])
    batch = best_raw.recognize_trials(partial, top_k=1)
    assert [used for used, _ in batch.procedure_fields()] == [["tap", "squeeze"]] * len(whole)
    right = batch.top_index[:, 0] == test_trials.labels
    assert right.mean() >= 0.6


def test_a_featurizer_learns_from_whole_trials_only(train):
    trials = list(train.trials)
    trials[2] = _without(trials[2], 0)
    with pytest.raises(RawTrialError, match="lacks phase\\(s\\) tap") as err:
        TactileImageFeaturizer().fit(trials)
    assert (err.value.trial, err.value.channel) == (2, "phases")
