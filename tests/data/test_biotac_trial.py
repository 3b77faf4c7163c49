"""Raw BioTac trials: the validator's every error names trial, finger and channel; the
phase rule on signals whose contacts are known; HDF5 write then read gives the same trial."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from app.data.biotac import (
    CHANNELS,
    FingerSignals,
    PhaseRule,
    RawTrial,
    RawTrialError,
    parse_trial,
    parse_trials,
    pressure_from_group,
    read_biotac_h5,
    write_biotac_h5,
)
from app.data.dataset import DatasetError

from .biotac_samples import CONTACTS, REST, finger_data, synthetic_trial, trial_data


def test_json_trial_is_parsed_to_float32_channels():
    data = json.loads(json.dumps(trial_data()))  # exactly what an HTTP body carries
    trial = parse_trial(data)
    assert trial.n_fingers == 2 and trial.n_frames == 800 and trial.phases is None
    f = trial.fingers[1]
    assert f.pac.shape == (800, 22) and f.electrodes.shape == (800, 19) and f.pdc.shape == (800,)
    assert all(getattr(f, c).dtype == np.float32 for c in CHANNELS)
    np.testing.assert_array_equal(f.pac, np.asarray(data["fingers"][1]["pac"], np.float32))
    assert parse_trial(trial.to_dict()).same_as(trial)


def test_one_finger_and_given_phases_and_timestamps():
    data = trial_data(n_fingers=1)
    data["phases"] = [[10, 40], [50, 60]]
    data["timestamps"] = list(range(800))
    trial = parse_trial(data)
    assert trial.n_fingers == 1 and trial.phases == ((10, 40), (50, 60))
    assert trial.phase_bounds() == (((10, 40), (50, 60)),)  # given phases win over the rule
    np.testing.assert_array_equal(trial.timestamps, np.arange(800))


def test_unix_timestamps_are_kept_to_the_second():
    # the pilot's frames carry whole Unix seconds near 1.34e9, where float32 steps by 128
    data = trial_data(n_fingers=1)
    data["timestamps"] = [1_342_570_368 + i // 100 for i in range(800)]
    trial = parse_trial(data)
    assert trial.timestamps.dtype == np.float64
    assert trial.timestamps[-1] - trial.timestamps[0] == 7


def _bad(mutate, trial=None, **kwargs):
    data = trial_data(**kwargs)
    mutate(data)
    with pytest.raises(RawTrialError) as err:
        parse_trial(data, trial=trial)
    assert isinstance(err.value, DatasetError) and isinstance(err.value, ValueError)
    return err.value


def _set(finger: int, channel: str, value):
    def mutate(data):
        data["fingers"][finger][channel] = value

    return mutate


def test_missing_channel():
    err = _bad(lambda d: d["fingers"][1].pop("pac"), trial=3)
    assert (err.trial, err.finger, err.channel) == (3, 1, "pac")
    assert str(err).startswith("trial 3, finger 1, channel 'pac': missing channel")


def test_misnamed_channel():
    def mutate(d):
        d["fingers"][0]["electrode"] = d["fingers"][0].pop("electrodes")

    err = _bad(mutate, trial=0)
    assert (err.trial, err.finger, err.channel) == (0, 0, "electrode")
    assert "did you mean 'electrodes'" in str(err)


@pytest.mark.parametrize(
    ("channel", "value", "expected"),
    [
        ("pac", np.zeros((800, 21)).tolist(),
         "expected 22 columns per frame (shape (T, 22)), got 21"),
        ("electrodes", np.zeros((800, 18)).tolist(), "expected 19 columns per frame"),
        ("electrodes", np.zeros(800).tolist(), "got shape (800,)"),
        ("pdc", np.zeros((800, 1)).tolist(), "expected one value per frame (shape (T,))"),
    ],
)  # fmt: skip
def test_wrong_width(channel, value, expected):
    err = _bad(_set(1, channel, value), trial=2)
    assert (err.trial, err.finger, err.channel) == (2, 1, channel)
    assert expected in str(err)


def test_mismatched_lengths_within_a_finger():
    err = _bad(_set(0, "tdc", np.zeros(799).tolist()), trial=5)
    assert (err.trial, err.finger, err.channel) == (5, 0, "tdc")
    assert "has 799 frames where 'pdc' has 800" in str(err)


def test_mismatched_lengths_between_fingers():
    data = trial_data()
    data["fingers"][1] = {k: v[:700] for k, v in data["fingers"][1].items()}
    with pytest.raises(RawTrialError) as err:
        parse_trial(data, trial=1)
    assert (err.value.trial, err.value.finger, err.value.channel) == (1, 1, "pdc")
    assert "700 frames where finger 0 has 800" in str(err.value)


@pytest.mark.parametrize(("value", "word"), [(float("nan"), "NaN"), (float("inf"), "infinite"),
                                             (1e300, "infinite")])  # fmt: skip
def test_nan_or_infinity(value, word):
    def mutate(d):
        d["fingers"][1]["tac"][5] = value

    err = _bad(mutate, trial=4)
    assert (err.trial, err.finger, err.channel) == (4, 1, "tac")
    assert f"frame 5 is {word}" in str(err)


def test_nan_inside_a_wide_channel_names_its_frame():
    def mutate(d):
        d["fingers"][0]["electrodes"][7][3] = float("nan")

    err = _bad(mutate)
    assert (err.finger, err.channel) == (0, "electrodes") and "frame 7 is NaN" in str(err)


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (["1", "2"], "values must be numbers"),
        ([1.0, None], "values must all be numbers"),
        ([[1.0] * 22, [1.0] * 21], "rows have different lengths"),
        ([True, False], "values must be numbers"),
    ],
)  # fmt: skip
def test_non_numeric_or_ragged_values(value, expected):
    channel = "pac" if isinstance(value[0], list) else "pdc"
    err = _bad(_set(0, channel, value), trial=0)
    assert (err.finger, err.channel) == (0, channel) and expected in str(err)


def test_finger_too_short():
    data = trial_data()
    data["fingers"] = [{k: v[:1] for k, v in f.items()} for f in data["fingers"]]
    with pytest.raises(RawTrialError, match="too short: 1 frame") as err:
        parse_trial(data, trial=6)
    assert (err.value.trial, err.value.finger, err.value.channel) == (6, 0, "pdc")


def test_finger_too_short_to_find_phases():
    data = trial_data(n_frames=90, contacts=((50, 60),))
    with pytest.raises(RawTrialError, match="too short to find phases") as err:
        parse_trial(data, trial=0)
    assert (err.value.finger, err.value.channel) == (0, "pdc")
    # with phases given, the same 90 frames are a valid trial
    data["phases"] = [[50, 60]]
    assert parse_trial(data).phases == ((50, 60),)


def test_finger_without_contact():
    data = trial_data()
    data["fingers"][1]["pdc"] = [REST] * 800
    with pytest.raises(RawTrialError, match="no contact to find a phase in") as err:
        parse_trial(data, trial=9)
    assert (err.value.trial, err.value.finger, err.value.channel) == (9, 1, "pdc")
    # without the check, the trial itself is valid (phases may come later)
    assert parse_trial(data, check_phases=False).n_fingers == 2


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({}, "missing field 'fingers'"),
        ({"fingers": []}, "'fingers' is empty"),
        ({"fingers": {"pdc": [1]}}, "'fingers' must be a list"),
        ({"fingers": [[1, 2]]}, "a finger must be an object of channels"),
        ({"fingers": [], "finger": []}, "unknown field 'finger'"),
        ([1, 2], "a trial must be an object"),
    ],
)  # fmt: skip
def test_malformed_trial_objects(data, expected):
    with pytest.raises(RawTrialError, match=expected) as err:
        parse_trial(data, trial=2)
    assert err.value.trial == 2 and str(err.value).startswith("trial 2")


@pytest.mark.parametrize(
    ("phases", "expected"),
    [
        ([[10, 5]], r"phase 0 is \[10, 5\)"),
        ([[0, 801]], r"phase 0 is \[0, 801\)"),
        ([[10, 50], [40, 60]], "starts before phase 0 ends"),
        ([10, 50], "phase 0 is not a \\[start, end\\] pair"),
        ([], "non-empty list"),
        ([[1.5, 3]], "whole frame numbers"),
        ([["a", "b"]], "phase 0 is not a \\[start, end\\] pair"),
        ([None, None], "every phase is null"),
        ([[10, 50], None, [40, 60]], "phase 2 .* starts before phase 0 ends"),
        ("10-50", "expected a list of \\[start, end\\] pairs, got str"),
    ],
)  # fmt: skip
def test_bad_phases(phases, expected):
    data = trial_data()
    data["phases"] = phases
    with pytest.raises(RawTrialError, match=expected) as err:
        parse_trial(data, trial=1)
    assert (err.value.trial, err.value.channel) == (1, "phases")


def test_a_phase_not_done_is_null_and_comes_back_as_null():
    data = trial_data()
    data["phases"] = [[10, 40], None, [60, 90]]
    trial = parse_trial(data)
    assert trial.phases == ((10, 40), None, (60, 90))
    assert trial.to_dict()["phases"] == [[10, 40], None, [60, 90]]
    assert parse_trial(trial.to_dict()).same_as(trial)


def test_timestamps_of_the_wrong_length():
    data = trial_data()
    data["timestamps"] = [0.0] * 10
    with pytest.raises(RawTrialError, match=r"expected shape \(800,\)") as err:
        parse_trial(data, trial=0)
    assert err.value.channel == "timestamps"


def test_parse_trials_names_the_index():
    good = trial_data()
    bad = trial_data()
    bad["fingers"][0].pop("tdc")
    with pytest.raises(RawTrialError) as err:
        parse_trials([good, good, bad])
    assert (err.value.trial, err.value.finger, err.value.channel) == (2, 0, "tdc")
    assert len(parse_trials([good, good])) == 2


def test_arrays_and_finger_objects_are_accepted():
    arrays = finger_data()
    trial = RawTrial(fingers=(FingerSignals(**arrays), arrays))
    np.testing.assert_array_equal(trial.fingers[0].pdc, trial.fingers[1].pdc)


# ------------------------------------------------------------------------ phase rule
def test_rule_finds_the_constructed_contacts():
    assert PhaseRule().find(finger_data()["pdc"]) == CONTACTS


def test_rule_merges_short_dips_and_ignores_twitches():
    pdc = finger_data()["pdc"]
    pdc[400:405] = REST  # a 5-frame dip inside the hold
    pdc[250:256] += 15  # a twitch: above the contact level, far below the peak
    assert PhaseRule().find(pdc) == CONTACTS
    with pytest.raises(RawTrialError, match=r"found 4 contact\(s\)"):
        PhaseRule(min_gap=0).find(pdc)  # the dip splits the hold


def test_rule_counts_contacts():
    pdc = finger_data(contacts=((150, 170), (300, 500)))["pdc"]
    with pytest.raises(
        RawTrialError,
        match=r"found 2 contact\(s\) \(\[150, 170\), \[300, 500\)\)"
        " where 3 exploration phases are expected",
    ):
        PhaseRule().find(pdc)
    assert PhaseRule(n_phases=2).find(pdc) == ((150, 170), (300, 500))


def test_rule_parameters_are_validated():
    with pytest.raises(ValueError, match="n_phases must be an integer >= 1"):
        PhaseRule(n_phases=0)
    with pytest.raises(ValueError, match="peak_fraction must lie in"):
        PhaseRule(peak_fraction=1.5)
    with pytest.raises(ValueError, match="contact_counts must be > 0"):
        PhaseRule(contact_counts=float("nan"))


def test_pressure_in_group_names():
    assert pressure_from_group("cork_pdc150_1cm_02") == 150.0
    assert pressure_from_group("glass_bottle_pdc100_1cm_05") == 100.0
    assert np.isnan(pressure_from_group("trial_07"))


# ------------------------------------------------------------------------------ HDF5
def test_hdf5_write_then_read_is_identical(tmp_path):
    with_extras = parse_trial(
        {
            **trial_data(seed=3),
            "phases": [[150, 170], [300, 500]],
            "timestamps": (np.arange(800) / 100).tolist(),
        }
    )
    trials = {
        "obj_pdc100_1cm_01": synthetic_trial(),
        "obj_pdc200_1cm_01": with_extras,
        "one_finger": synthetic_trial(n_fingers=1, seed=7),
    }
    write_biotac_h5(tmp_path / "obj.h5", trials)
    back = read_biotac_h5(tmp_path / "obj.h5")
    assert list(back) == sorted(trials)
    for name, trial in trials.items():
        assert back[name].same_as(trial), name
    assert not back["obj_pdc100_1cm_01"].same_as(with_extras)


def _write_raw(path, mutate):
    """An HDF5 trial in the pilot layout, changed by ``mutate(finger_group_1)``."""
    arrays = finger_data()
    with h5py.File(path, "w") as fh:
        group = fh.create_group("cork_pdc100_1cm_01")
        group.create_dataset("timestamps", data=np.arange(800))
        for i in range(2):
            sub = group.create_group(f"finger_{i}")
            for k, v in arrays.items():
                sub.create_dataset(k, data=v.astype(np.int64))
        mutate(group["finger_1"])


@pytest.mark.parametrize(
    ("mutate", "channel", "expected"),
    [
        (lambda g: g.__delitem__("pac"), "pac", "missing channel"),
        (lambda g: g.move("tdc", "tdc_raw"), "tdc_raw", "unknown channel (did you mean 'tdc'?)"),
        (lambda g: (g.__delitem__("electrodes"),
                    g.create_dataset("electrodes", data=np.zeros((800, 18)))),
         "electrodes", "expected 19 columns"),
        (lambda g: (g.__delitem__("tac"), g.create_dataset("tac", data=np.zeros(10))), "tac",
         "has 10 frames"),
    ],
)  # fmt: skip
def test_hdf5_errors_name_file_group_finger_and_channel(tmp_path, mutate, channel, expected):
    path = tmp_path / "cork.h5"
    _write_raw(path, mutate)
    with pytest.raises(RawTrialError) as err:
        read_biotac_h5(path)
    e = err.value
    assert (e.file, e.group, e.finger, e.channel) == (str(path), "cork_pdc100_1cm_01", 1, channel)
    assert str(e).startswith(f"{path}, group 'cork_pdc100_1cm_01', finger 1, channel '{channel}'")
    assert expected in str(e)


def test_hdf5_file_that_is_not_hdf5(tmp_path):
    (tmp_path / "x.h5").write_text("not hdf5")
    with pytest.raises(RawTrialError, match="cannot read as HDF5") as err:
        read_biotac_h5(tmp_path / "x.h5")
    assert err.value.file == str(tmp_path / "x.h5")


def test_hdf5_group_without_fingers(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w") as fh:
        fh.create_group("t1").create_dataset("timestamps", data=np.arange(3))
    with pytest.raises(RawTrialError, match="group 't1': no finger group"):
        read_biotac_h5(tmp_path / "x.h5")
