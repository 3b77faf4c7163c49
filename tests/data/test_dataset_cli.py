"""``tactile-zsl dataset check|export``: summaries, exports that load back identical, and
bad datasets exiting 2 with a message naming the file, the row or group and the field."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest

from app.cli import main
from app.data.biotac import write_biotac_folder
from app.data.folder import load_folder, write_folder
from app.data.sources import load_dataset

from .test_folder import assert_same, graded_dataset, small_biotac
from .test_phac2 import write_fake_phac2


def run(capsys, *argv: str) -> tuple[int, dict | None, str]:
    code = main(["dataset", *argv])
    out, err = capsys.readouterr()
    return code, json.loads(out) if code == 0 else None, err


def test_check_simulated(capsys):
    code, summary, _ = run(capsys, "check", "simulated:4")
    assert code == 0 and summary["objects"] == 4 and summary["samples"] == 40
    assert summary["input_shape"] == [32, 30] and summary["attributes"]["binary"] is True


def test_check_folder_with_graded_values(tmp_path, capsys):
    write_folder(graded_dataset(), tmp_path)
    code, summary, _ = run(capsys, "check", f"folder:{tmp_path}")
    assert code == 0 and summary["trials"] == 4 and summary["input_shape"] == [4, 5]
    assert summary["attributes"] == {
        "count": 3,
        "names": ["hard", "soft", "rough"],
        "binary": False,
        "graded_values": 3,
        "not_known_values": 2,
    }


def test_check_biotac_lists_raw_channels_and_pressures(tmp_path, capsys):
    write_biotac_folder(small_biotac(), tmp_path)
    code, summary, _ = run(capsys, "check", f"biotac:{tmp_path}")
    assert code == 0 and summary["form"] == "raw BioTac trials"
    assert (
        summary["trials"] == 6 and summary["samples"] == 12 and summary["image_shape"] == [24, 30]
    )
    assert summary["raw_channels"]["pac"] == "(T, 22)" and summary["frames"] == {
        "min": 800,
        "max": 800,
    }
    assert summary["grip_pressure"] == {"100": 3, "150": 1, "200": 1, "unknown": 1}


@pytest.mark.parametrize("kind", ["simulated", "phac2", "biotac"])
def test_export_loads_back_identical(tmp_path, capsys, kind):
    if kind == "simulated":
        spec = "simulated:5"
    elif kind == "phac2":
        spec = f"phac2:{write_fake_phac2(tmp_path / 'phac2')}"
    else:
        write_biotac_folder(small_biotac(), tmp_path / "raw")
        spec = f"biotac:{tmp_path / 'raw'}"
    code, summary, _ = run(
        capsys, "export", "--dataset", spec, "--out", str(tmp_path / "out"), "--seed", "3"
    )
    assert code == 0 and summary["spec"] == f"folder:{tmp_path / 'out'}"
    assert_same(load_dataset(spec, seed=3), load_folder(tmp_path / "out"))
    code, _, err = run(capsys, "export", "--dataset", spec, "--out", str(tmp_path / "out"))
    assert code == 2 and "already holds objects.csv" in err


def test_export_help_says_how_raw_trials_are_featurized(capsys):
    with pytest.raises(SystemExit):
        main(["dataset", "export", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "fitted on all of the dataset's trials" in text and "one per finger" in text


# ------------------------------------------------------------------- bad datasets
def test_bad_folder_exits_2_naming_file_row_and_field(tmp_path, capsys):
    write_folder(graded_dataset(), tmp_path)
    text = (tmp_path / "samples.csv").read_text().replace("felt,2", "velvet,2")
    (tmp_path / "samples.csv").write_text(text)
    code, _, err = run(capsys, "check", f"folder:{tmp_path}")
    assert code == 2
    assert err.strip() == (f"tactile-zsl dataset: error: {tmp_path / 'samples.csv'}, row 6, "
                           "field 'object': object 'velvet' is not in objects.csv")  # fmt: skip


def test_bad_objects_csv_value_exits_2(tmp_path, capsys):
    write_folder(graded_dataset(), tmp_path)
    text = (tmp_path / "objects.csv").read_text().replace("301,brick,1,0", "301,brick,1,-1")
    (tmp_path / "objects.csv").write_text(text)
    code, _, err = run(capsys, "check", f"folder:{tmp_path}")
    assert code == 2 and f"{tmp_path / 'objects.csv'}, row 2, field 'soft': '-1'" in err


def _break_channel(path, group, finger, channel, data):
    with h5py.File(path, "a") as fh:
        node = fh[group][f"finger_{finger}"]
        del node[channel]
        if data is not None:
            node.create_dataset(channel, data=data)


@pytest.mark.parametrize(
    ("channel", "data", "words"),
    [
        ("pac", None, "channel 'pac': missing channel"),
        ("electrodes", np.zeros((800, 20)), "channel 'electrodes': expected 19 columns"),
        ("tdc", np.zeros(799), "channel 'tdc': has 799 frames where 'pdc' has 800"),
        ("tac", np.r_[np.zeros(799), np.nan], "channel 'tac': frame 799 is NaN"),
        ("pdc", np.full(800, 800.0), "channel 'pdc': no contact to find a phase in"),
    ],
)  # fmt: skip
def test_bad_biotac_exits_2_naming_file_group_finger_and_channel(
    tmp_path, capsys, channel, data, words
):
    write_biotac_folder(small_biotac(), tmp_path)
    _break_channel(tmp_path / "foam.h5", "foam_pdc100_1cm_02", 1, channel, data)
    code, _, err = run(capsys, "check", f"biotac:{tmp_path}")
    assert code == 2
    prefix = (
        f"tactile-zsl dataset: error: {tmp_path / 'foam.h5'}, "
        "group 'foam_pdc100_1cm_02', finger 1, "
    )
    assert err.strip().startswith(prefix + words), err


def test_bad_specs_exit_2(capsys, tmp_path):
    for spec, words in [
        ("folder:", "'folder' needs a folder"),
        ("biotac:", "'biotac' needs a folder"),
        (f"folder:{tmp_path / 'absent'}", "dataset folder not found"),
        ("hdf5:x", "unknown dataset kind 'hdf5'"),
    ]:
        code, _, err = run(capsys, "check", spec)
        assert code == 2 and words in err


def test_console_script_exit_status(tmp_path):
    write_folder(graded_dataset(), tmp_path)
    (tmp_path / "samples.csv").write_text("object,trial\nbrick,x\n")
    done = subprocess.run(
        [sys.executable, "-m", "app.cli", "dataset", "check", f"folder:{tmp_path}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert (
        f"{tmp_path / 'samples.csv'}, row 2, field 'trial': trial 'x' is not an integer"
        in done.stderr
    )
