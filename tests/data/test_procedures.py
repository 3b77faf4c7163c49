"""Procedures are named in the data: PHAC-2's phases, the simulator's four, a folder's
procedures.txt; blocks, missing procedures and their errors."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from app.data.dataset import DatasetError, DatasetFileError
from app.data.folder import PROCEDURES_FILE, load_folder, write_folder
from app.data.procedures import ProcedureError, keep_only, present
from app.data.simulator import simulate_dataset

PHAC2 = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "phac2"


def test_phac2_samples_carry_the_files_four_phases():
    from app.data.phac2 import load_phac2

    data = load_phac2(PHAC2)
    assert data.procedures == (
        "SQUEEZE_SET_PRESSURE_SLOW",
        "HOLD_FOR_10_SECONDS",
        "SLIDE_5CM",
        "MOVE_DOWN_5CM",
    )
    hold = data.procedure_view(1)
    raw = np.load(PHAC2 / "phac2_static_features.npz")["features"]
    np.testing.assert_array_equal(hold.samples, raw[:, 1].astype(np.float32))
    assert hold.procedures == ("HOLD_FOR_10_SECONDS",)
    assert data.subset(data.labels < 3).select_classes([0, 2]).procedures == data.procedures


def test_simulated_samples_hold_four_blocks_of_eight_readings():
    data = simulate_dataset(n_objects=3, trials_per_object=2)
    assert data.procedures == ("squeeze", "hold", "slide", "move_down")
    np.testing.assert_array_equal(data.procedure_view(2).samples, data.samples[:, 16:24])


def test_a_folder_names_its_procedures_in_procedures_txt(tmp_path):
    data = simulate_dataset(n_objects=3, trials_per_object=2)
    write_folder(data, tmp_path)
    assert (tmp_path / PROCEDURES_FILE).read_text() == "squeeze\nhold\nslide\nmove_down\n"
    assert load_folder(tmp_path).procedures == data.procedures
    (tmp_path / PROCEDURES_FILE).write_text("press\nstroke\n\n")  # 2 blocks of 16 rows
    assert load_folder(tmp_path).procedures == ("press", "stroke")
    (tmp_path / PROCEDURES_FILE).unlink()
    assert load_folder(tmp_path).procedures == ()


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("a\nb\nc\n", "3 procedures do not split a sample's first axis of 32"),
        ("a\na\n", "repeated: a"),
    ],
)
def test_a_procedures_txt_that_does_not_fit_is_named(tmp_path, text, why):
    write_folder(simulate_dataset(n_objects=3, trials_per_object=2), tmp_path)
    (tmp_path / PROCEDURES_FILE).write_text(text)
    with pytest.raises(DatasetFileError, match=why) as info:
        load_folder(tmp_path)
    assert info.value.file.endswith(PROCEDURES_FILE)


def test_a_dataset_refuses_procedures_that_do_not_split_its_samples():
    data = simulate_dataset(n_objects=3, trials_per_object=2)
    with pytest.raises(DatasetError, match="5 procedures do not split"):
        dataclasses.replace(data, procedures=("a", "b", "c", "d", "e"))


def test_missing_procedures_are_whole_nan_blocks():
    names = ("a", "b", "c")
    x = np.arange(2 * 6 * 2, dtype=np.float32).reshape(2, 6, 2)
    kept = keep_only(x, names, [1])
    assert present(kept, names).tolist() == [[False, True, False]] * 2
    np.testing.assert_array_equal(kept[:, 2:4], x[:, 2:4])
    kept[1, 2, 0] = np.nan
    with pytest.raises(ProcedureError, match="sample 1: procedure 'b' is partly missing") as info:
        present(kept, names)
    assert (info.value.sample, info.value.procedure) == (1, "b")
    with pytest.raises(ProcedureError, match="sample 0: every procedure is missing"):
        present(np.full_like(x, np.nan), names)


def test_dataset_check_lists_the_procedures(capsys):
    from app.cli import main

    assert main(["dataset", "check", "simulated:4"]) == 0
    assert json.loads(capsys.readouterr().out)["procedures"] == [
        "squeeze",
        "hold",
        "slide",
        "move_down",
    ]
