"""``evaluate --procedures``: figures for every subset of procedures and for the adaptive
rule, with the robot time it used (app/evaluation/procedures.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.cli import main
from app.data.simulator import simulate_dataset
from app.evaluation.procedures import (
    DURATIONS,
    TARGETS,
    check_durations,
    explore,
    procedure_figures,
    subsets,
)
from app.evaluation.protocol import evaluate
from app.evaluation.report import write_report
from app.framework.recognizer import MIN_PROCEDURES
from app.framework.registry import make_method
from tests.evaluation.tables import empty_definitions, empty_markdown_rows

FAST = {"n_estimators": 20, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def dataset():
    return simulate_dataset(n_objects=16, trials_per_object=5, seed=2)


@pytest.fixture(scope="module")
def results(dataset):
    return evaluate(
        dataset,
        ["best"],
        n_novel=4,
        n_splits=2,
        seed=3,
        method_params={"best": FAST},
        progress=False,
        ceilings=True,
        procedures=True,
    )


def test_all_procedures_give_the_protocols_own_figures(results):
    assert results["procedures"] == ["squeeze", "hold", "slide", "move_down"]
    assert results["durations"] == [DURATIONS[p] for p in results["procedures"]]
    for split in results["methods"]["best"]["splits"]:
        for figure in ("known_acc", "nd_novel_detected", "zsl", "gzsl_h"):
            assert split[f"procs1111_{figure}"] == pytest.approx(split[figure], abs=1e-12)
        assert split["procs1111_nd_known_kept"] == pytest.approx(split["nd_test_kept"])
    assert set(procedure_figures(4)) <= set(results["methods"]["best"]["ci95"])


def test_the_adaptive_rule_uses_more_time_for_a_higher_target(results):
    mean = results["methods"]["best"]["mean"]
    times = [mean[f"adaptive{round(t * 100)}_time"] for t in TARGETS]
    assert all(0 < t <= 1 for t in times) and times == sorted(times)
    shortest = min(DURATIONS[p] for p in results["procedures"]) / sum(results["durations"])
    assert times[0] >= shortest
    ci95 = results["methods"]["best"]["ci95"]
    for t in TARGETS:
        count = f"adaptive{round(t * 100)}_procedures"
        assert MIN_PROCEDURES <= mean[count] <= 4
        # a count of procedures, not a share: its interval is not cut at 1
        assert ci95[count][0] <= mean[count] <= ci95[count][1]


def test_explore_starts_with_the_first_procedure_and_stops_when_sure(dataset):
    model = make_method("best", **FAST).fit(dataset)
    x = dataset.samples[:10]
    sure = explore(model, x, 1e-9)  # sure at once: stops after MIN_PROCEDURES
    first = dataset.procedures.index(model.first_procedure)
    assert sure.sum(axis=1).tolist() == [MIN_PROCEDURES] * 10 and sure[:, first].all()
    never = explore(model, x + np.float32(3.0), 1.0)  # unlike any training sample
    assert never.all()


def test_the_report_tabulates_and_draws_the_procedures(results, tmp_path):
    files = write_report(results, tmp_path)
    text = files[0].read_text()
    assert "## Figures against the procedures used" in text
    assert text.count("\n| 1 + 2 + 3 + 4 |") == 1
    # the 342 procedure figures stay in their section: not rows of the tables of means, nor
    # columns of the per-split table; the figure list names their families once
    assert "| `procs" not in text and "`procs1111_known_acc` |" not in text
    assert "- `procs<bits>_<figure>`: the figure with only the procedures" in text
    assert empty_markdown_rows(text) == [] and empty_definitions(text) == []
    assert "| `ceil_gzsl_h` |" in text  # the --ceilings asked for are there
    png = tmp_path / "procedures.png"
    assert png in files and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_procedures_need_names_and_durations(dataset):
    assert len(subsets(4)) == 15 and procedure_figures(1) == ()
    with pytest.raises(ValueError, match="--durations press=SECONDS"):
        check_durations(["press"], {})
    assert check_durations(["press", "hold"], {"press": 2.5}).tolist() == [2.5, 10.0]
    plain = dataclasses.replace(dataset, procedures=())
    with pytest.raises(ValueError, match="names 0 procedures"):
        evaluate(plain, ["best"], n_novel=4, n_splits=1, progress=False, procedures=True)


def test_bad_durations_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(["evaluate", "--dataset", "simulated:8", "--procedures", "--durations", "hold=-1"])
    assert info.value.code == 2
    assert "NAME=SECONDS with SECONDS > 0" in capsys.readouterr().err
