"""``evaluate --tables``: tables of objects named jointly and one by one
(app/evaluation/tables.py), beside the protocol's own figures."""

from __future__ import annotations

import numpy as np
import pytest

from app.cli import main as cli_main
from app.data.simulator import simulate_dataset
from app.evaluation import metrics
from app.evaluation.protocol import evaluate
from app.evaluation.summary import summary_table
from app.evaluation.tables import (
    TABLE_FIGURES,
    joint_accuracy,
    mixed_draws,
    novel_tables,
)

FAST = {"n_estimators": 20, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def dataset():
    return simulate_dataset(n_objects=16, trials_per_object=5, seed=2)


def test_tables_deal_k_distinct_trials_of_every_object():
    labels = np.repeat([0, 1, 2], 5)
    trials = np.r_[np.arange(5), np.arange(10, 15), np.array([20, 21, 22, 23, 23])]
    tables = novel_tables(labels, trials, 2, np.random.default_rng(0))
    # object 2 has 4 distinct trials: 2 hands of 2; the others 2 hands too
    assert len(tables) == 2
    used = set()
    for table in tables:
        assert [int(labels[rows[0]]) for rows in table] == [0, 1, 2]
        for rows in table:
            assert len(set(labels[rows])) == 1 and len(set(trials[rows])) == 2
            assert not used & set(rows.tolist())  # a trial serves one table only
            used |= set(rows.tolist())
    assert len(novel_tables(labels, trials, 1, np.random.default_rng(0))) == 4


def test_joint_accuracy_against_alone():
    # both objects prefer class 0; jointly the second takes its next best
    log_p = np.log(np.array([[0.8, 0.2], [0.6, 0.4]]))
    assert joint_accuracy(log_p, np.array([0, 1])) == (1.0, 0.5)


def test_mixed_draws_take_one_trial_of_as_many_known_objects():
    yk = np.repeat(np.arange(10), 2)
    yn = np.repeat(np.arange(3), 4)
    for ki, ni in mixed_draws(yk, yn, np.random.default_rng(1), 5):
        assert len(set(yk[ki])) == 3 and len(ki) == 3
        assert sorted(yn[ni].tolist()) == [0, 1, 2]


def test_tables_add_figures_and_change_none_of_the_others(dataset):
    common = dict(
        n_novel=4,
        n_splits=2,
        seed=3,
        test_trials=2,
        method_params={"best": FAST},
        progress=False,
    )
    plain = evaluate(dataset, ["best"], **common)
    tables = evaluate(dataset, ["best"], tables=True, **common)
    assert tables["tables"] is True and plain["tables"] is False
    for before, after in zip(
        plain["methods"]["best"]["splits"], tables["methods"]["best"]["splits"], strict=True
    ):
        assert {k: v for k, v in after.items() if not k.startswith("tables")} == before
        for f in TABLE_FIGURES:
            assert 0.0 <= after[f] <= 1.0, f
        assert after["tables_mixed_gzsl_h"] == pytest.approx(
            metrics.harmonic_mean(
                after["tables_mixed_gzsl_seen"], after["tables_mixed_gzsl_unseen"]
            )
        )
    mean = tables["methods"]["best"]["mean"]
    assert set(TABLE_FIGURES) <= set(mean)
    printed = summary_table(tables)
    assert "tables1_zsl_joint" in printed and "tables_mixed_gzsl_h" in printed


def test_one_touch_tables_alone_is_zsl_on_every_test_trial(dataset):
    # every novel test trial is in exactly one 1-touch table, so alone is the protocol's zsl
    results = evaluate(
        dataset,
        ["best"],
        n_novel=4,
        n_splits=1,
        seed=5,
        test_trials=2,
        method_params={"best": FAST},
        progress=False,
        tables=True,
    )
    split = results["methods"]["best"]["splits"][0]
    assert split["tables1_zsl_alone"] == pytest.approx(split["zsl"])


def test_tables_on_raw_trials_exit_2(tmp_path, capsys):
    from tests.framework.raw_data import pilot_path

    code = cli_main(
        [
            "evaluate",
            "--dataset",
            f"biotac:{pilot_path()}",
            "--tables",
            "--no-progress",
            "--out",
            str(tmp_path / "r.json"),
        ]
    )
    assert code == 2
    assert "as --tables does, not to raw BioTac trials" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()
