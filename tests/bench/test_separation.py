"""bench/separation.py at tiny sizes: a record per dataset and size, the table, the plot,
and clear refusals of bad arguments. The figures mean little at this size."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench import separation


def test_tiny_sizes_give_every_figure_a_table_and_a_plot(tmp_path, capsys):
    assert separation.main(["--sizes", "20,30", "--trials", "3", "--nn1-max", "20",
                            "--phac2", "", "--out", str(tmp_path)]) == 0  # fmt: skip
    records = json.loads((tmp_path / "separation.json").read_text())["records"]
    assert [(r["separation"], r["objects"]) for r in records] == [
        ("none", 20), ("none", 30), ("phac2", 20), ("phac2", 30)
    ]  # fmt: skip
    for r in records:
        assert r["trials"] == 3 * r["objects"] and r["features"] == 960
        assert 0 <= r["sep_q10"] <= r["sep_q25"] <= r["sep_median"] <= r["sep_q75"]
        assert sum(r["sep_hist"]) <= r["objects"]
        assert ("nn1" in r) == (r["objects"] <= 20)
    assert capsys.readouterr().out.startswith("| data | separation | objects | sep_median |")
    assert (tmp_path / "separation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_statistic_sees_objects_move_apart():
    """Two tight clusters of objects drawn apart by a growing margin: the statistic grows,
    and objects identical to another have 0."""
    rng = np.random.default_rng(0)
    centres = rng.normal(0.0, 1.0, (20, 8))
    labels = np.repeat(np.arange(20), 10)
    noise = rng.normal(0.0, 1.0, (200, 8))
    near = separation.statistic(centres[labels] * 0.5 + noise, labels, nn1=False)
    far = separation.statistic(centres[labels] * 5.0 + noise, labels)
    assert far["sep_median"] > 4 * near["sep_median"] and far["nn1"] > 0.9
    twins = centres.copy()
    twins[1], twins[3] = twins[0], twins[2]  # 4 of 20 objects: the 10th percentile is 0
    same = separation.statistic(twins[labels] * 5.0 + noise * 0.01, labels, nn1=False)
    assert same["sep_q10"] < 1.0 < same["sep_median"]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--sizes", "1,10"], "at least 2 objects"),
        (["--sizes", "ten"], "--sizes must be integers"),
        (["--separations", "far"], "--separations takes none and phac2"),
        (["--trials", "1"], "--trials must be at least 2"),
    ],
)
def test_bad_arguments_exit_2_with_a_message(args, words, capsys, tmp_path):
    with pytest.raises(SystemExit) as stop:
        separation.main([*args, "--out", str(tmp_path)])
    assert stop.value.code == 2 and words in capsys.readouterr().err
