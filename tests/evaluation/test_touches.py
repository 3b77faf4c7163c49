"""``evaluate --touches``: figures after k touches of each test object answered as one, and
the mixed figure after one enrolled touch per novel object (app/evaluation/touches.py)."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.evaluation import metrics
from app.evaluation.protocol import evaluate, evaluate_split
from app.evaluation.report import write_report
from app.evaluation.splits import make_zsl_splits
from app.evaluation.touches import check_touches, measure, touch_groups
from app.framework.registry import make_method

FAST = {"n_estimators": 20, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def dataset():
    return simulate_dataset(n_objects=16, trials_per_object=5, seed=2)


def test_groups_hold_k_distinct_trials_of_one_object():
    objects = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1])
    trials = np.array([10, 11, 12, 13, 14, 20, 21, 22, 22])  # object 1: trial 22 twice
    group, n = touch_groups(objects, trials, 2, np.random.default_rng(0))
    assert n == 2 + 1  # object 0: 5 trials -> 2 groups; object 1: 3 trials -> 1 group
    for g in range(n):
        members = group == g
        assert len(set(objects[members])) == 1 and len(set(trials[members])) == 2
    left_out = np.unique(trials[group == -1])
    assert len(left_out) == 2  # one trial of each object fills no group
    whole, n1 = touch_groups(objects, trials, 1, np.random.default_rng(0))
    assert n1 == 8 and (whole >= 0).all()  # k = 1: every trial its own group


def test_touch_counts_are_checked_against_the_held_out_trials():
    assert check_touches([3, 1, 1], 3) == [1, 3]
    with pytest.raises(ValueError, match="--test-trials 3"):
        check_touches([1, 3], 2)
    with pytest.raises(ValueError, match="positive"):
        check_touches([0], 2)


def test_one_touch_gives_the_protocols_own_figures(dataset):
    results = evaluate(
        dataset,
        ["best"],
        n_novel=4,
        n_splits=2,
        seed=3,
        test_trials=2,
        method_params={"best": FAST},
        progress=False,
        ceilings=True,
        touches=[1, 2],
    )
    assert results["touches"] == [1, 2]
    for split in results["methods"]["best"]["splits"]:
        for figure in ("known_acc", "nd_novel_detected", "zsl", "gzsl_seen", "gzsl_unseen"):
            assert split[f"touches1_{figure}"] == pytest.approx(split[figure], abs=1e-12)
        assert split["touches1_nd_known_kept"] == pytest.approx(split["nd_test_kept"])
        assert 0 <= split["touches2_gzsl_h"] <= 1 and 0 <= split["osl_gzsl_h"] <= 1
    mean = results["methods"]["best"]["mean"]
    assert mean["touches2_known_acc"] >= mean["touches1_known_acc"] - 0.1
    assert "touches2_gzsl_h" in results["methods"]["best"]["ci95"]


def test_the_figures_are_the_models_own_answers(dataset):
    split = make_zsl_splits(dataset, 4, 1, seed=5, test_trials=2)[0]
    train = split.train_dataset(dataset)
    model = make_method("best", **FAST).fit(train)
    names = list(split.novel_names)
    zsl = model.add_novel_classes(names, split.novel_attributes(dataset), allow_known_vectors=True)
    osl = zsl
    for name, i in zip(names, split.one_shot_idx, strict=True):
        osl = osl.add_one_shot(name, dataset.samples[i : i + 1])
    ik, i_n = split.known_test_idx, split.novel_test_idx
    known = (dataset.samples[ik], split.known_labels(dataset, ik), dataset.trials[ik])
    novel = (dataset.samples[i_n], split.novel_labels(dataset, i_n), dataset.trials[i_n])
    figures = measure(
        zsl, osl, known, novel, train.class_names, names, [2], np.random.default_rng(0)
    )
    # after one enrolled touch: the one-shot model's answers on the mixed samples
    answers = osl.recognize(np.concatenate([known[0], novel[0]]), top_k=1)
    truth = [train.class_names[j] for j in known[1]] + [names[j] for j in novel[1]]
    right = np.array([a.class_name == t for a, t in zip(answers, truth, strict=True)])
    assert figures["osl_gzsl_seen"] == pytest.approx(right[: len(known[0])].mean())
    assert figures["osl_gzsl_unseen"] == pytest.approx(right[len(known[0]) :].mean())
    # two touches of a known object: the mean posterior of its two samples
    group, n = touch_groups(known[1], known[2], 2, np.random.default_rng(0))
    fused = [model.known_proba(known[0][group == g]).mean(axis=0).argmax() for g in range(n)]
    labels = [known[1][group == g][0] for g in range(n)]
    assert figures["touches2_known_acc"] == pytest.approx(np.mean(np.equal(fused, labels)))


def test_the_report_draws_the_curves(dataset, tmp_path):
    results = evaluate(
        dataset,
        ["best"],
        n_novel=4,
        n_splits=2,
        seed=1,
        method_params={"best": FAST},
        progress=False,
        touches=[1, 2],
    )
    written = write_report(results, tmp_path)
    png = tmp_path / "touches.png"
    assert png in written and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (tmp_path / "report.md").read_text()
    assert "touches.png" in report
    # the table: each touch count's mean, and the paired 2 - 1 difference over the splits
    splits = results["methods"]["best"]["splits"]
    diff = [s["touches2_zsl"] - s["touches1_zsl"] for s in splits]
    lo, hi = metrics.mean_interval(diff, bounds=(-1.0, 1.0))
    one = results["methods"]["best"]["mean"]["touches1_zsl"]
    assert "## Touches answered as one, and one enrolled touch" in report
    section = report[report.index("## Touches answered as one") :]
    row = next(line for line in section.splitlines() if line.startswith("| `zsl` | "))
    assert row.startswith(f"| `zsl` | {one:.3f} [")
    assert row.endswith(f"| {np.mean(diff):+.3f} [{lo:+.3f}, {hi:+.3f}] |")
    gain = [s["osl_gzsl_h"] - s["touches1_gzsl_h"] for s in splits]
    assert f"| {np.mean(gain):+.3f} [" in report


def test_evaluate_split_without_touches_adds_none(dataset):
    split = make_zsl_splits(dataset, 4, 1, seed=5, test_trials=2)[0]
    figures, _ = evaluate_split(dataset, split, "best", FAST)
    assert not any(k.startswith(("touches", "osl_gzsl")) for k in figures)


def test_more_touches_than_held_out_trials_exit_2_with_a_message(tmp_path, capsys):
    from app.cli import main

    args = ["evaluate", "--dataset", "simulated:12", "--splits", "1", "--methods", "best"]
    code = main([*args, "--touches", "1,3", "--out", str(tmp_path / "r.json"), "--no-progress"])
    assert code == 2
    assert "hold out that many with --test-trials 3" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()
