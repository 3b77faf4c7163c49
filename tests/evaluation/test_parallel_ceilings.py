"""``evaluate`` with real methods on the simulated dataset: --jobs 2 gives the figures of
--jobs 1, the ceilings bound the tuned figures on every split, and the command prints the
intervals, the paired differences and a line per split."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli import main
from app.data.simulator import simulate_dataset
from app.evaluation import metrics
from app.evaluation.protocol import CEILING_FIGURES, FIGURES, evaluate, make_recognizer

METHODS = ["eszsl", "best"]
ARGS = ["--dataset", "simulated:14", "--novel", "3", "--splits", "3", "--seed", "2"]


def _figures(value):
    """Everything but wall times (``timings``, ``elapsed_s``, ``*_s`` at any depth) and the
    number of processes."""
    if isinstance(value, dict):
        return {
            k: _figures(v)
            for k, v in value.items()
            if k not in ("timings", "jobs") and not k.endswith("_s")
        }
    if isinstance(value, list):
        return [_figures(v) for v in value]
    return value


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same command with --jobs 1 and --jobs 2 (results and printed output)."""
    root = tmp_path_factory.mktemp("jobs")
    out = {}
    for jobs in (1, 2):
        path = root / f"jobs{jobs}.json"
        code = main(
            [
                "evaluate",
                *ARGS,
                "--methods",
                ",".join(METHODS),
                "--ceilings",
                "--jobs",
                str(jobs),
                "--out",
                str(path),
                "--no-progress",
            ]
        )
        assert code == 0
        out[jobs] = json.loads(path.read_text())
    return out


def test_jobs_2_gives_the_figures_of_jobs_1(runs):
    one, two = runs[1], runs[2]
    assert one["jobs"] == 1 and two["jobs"] == 2
    assert _figures(one) == _figures(two)
    assert _figures(one)["methods"]["best"]["details"][0]["confusion_zsl"]  # details compared
    # not vacuous: the methods and splits differ from each other
    zsl = [s["zsl"] for m in METHODS for s in one["methods"][m]["splits"]]
    assert len(set(zsl)) > 1


def test_every_figure_has_its_interval_and_every_other_method_its_paired_difference(runs):
    res = runs[1]
    for m in METHODS:
        entry = res["methods"][m]
        for f in FIGURES + CEILING_FIGURES:
            low, high = entry["ci95"][f]
            values = [s[f] for s in entry["splits"]]
            assert low == pytest.approx(metrics.mean_interval(values, bounds=(0, 1))[0])
            assert 0.0 <= low <= entry["mean"][f] <= high <= 1.0, (m, f)
            # where a re-run of as many splits lands: wider than the confidence interval
            r_low, r_high = entry["rerun95"][f]
            assert [r_low, r_high] == list(metrics.rerun_interval(values, 3, bounds=(0, 1)))
            assert r_low <= low and r_high >= high, (m, f)
    assert res["rerun_splits"] == 3
    paired = res["paired"]
    assert paired["reference"] == "eszsl" and list(paired["methods"]) == ["best"]
    p = paired["methods"]["best"]
    for f in FIGURES:
        d = [
            b[f] - a[f]
            for a, b in zip(
                res["methods"]["eszsl"]["splits"], res["methods"]["best"]["splits"], strict=True
            )
        ]
        assert p["splits"][f] == pytest.approx(d)
        assert p["mean"][f] == pytest.approx(np.mean(d))
        assert p["ci95"][f] == pytest.approx(list(metrics.mean_interval(d, bounds=(-1, 1))))
    assert "intervals" in res and "Student" in res["intervals"]


def test_ceilings_bound_the_tuned_figures_on_every_split(runs):
    for m in METHODS:
        for s in runs[1]["methods"][m]["splits"]:
            assert s["ceil_gzsl_seen"] == s["known_acc"] >= s["gzsl_seen"]
            assert s["ceil_gzsl_unseen"] == s["zsl"] >= s["gzsl_unseen"]
            assert s["ceil_gzsl_h"] >= s["gzsl_h"]
            assert s["ceil_gzsl_h"] == pytest.approx(
                metrics.harmonic_mean(s["known_acc"], s["zsl"])
            )
            assert s["ceil_nd_balance"] >= s["nd_balance"]
            assert s["nd_balance"] == min(s["nd_test_kept"], s["nd_novel_detected"])
            assert s["ceil_nd_balance"] == min(s["ceil_nd_test_kept"], s["ceil_nd_novel_detected"])


def test_ceilings_recomputed_from_the_model():
    """ceil_nd_* and nd_test_kept of one split, from a model fitted apart from evaluate."""
    ds = simulate_dataset(n_objects=14, seed=0)
    res = evaluate(ds, ["eszsl"], n_novel=3, n_splits=1, seed=2, progress=False, ceilings=True)
    s = res["methods"]["eszsl"]["splits"][0]
    from app.evaluation.protocol import split_method_seed
    from app.evaluation.splits import make_zsl_splits

    split = make_zsl_splits(ds, 3, 1, 2)[0]
    own_seed = split_method_seed(2, 0)
    assert res["methods"]["eszsl"]["details"][0]["method_seed"] == own_seed
    model = make_recognizer("eszsl", None, own_seed).fit(split.train_dataset(ds))
    known = model.novelty_score(ds.samples[split.known_test_idx])
    novel = model.novelty_score(ds.samples[split.novel_test_idx])
    assert s["nd_test_kept"] == np.mean(known <= model.novelty_threshold)
    best = max(min(np.mean(known <= t), np.mean(novel > t)) for t in np.r_[-np.inf, known, novel])
    assert s["ceil_nd_balance"] == best
    # without --ceilings none of these figures is reported
    plain = evaluate(ds, ["eszsl"], n_novel=3, n_splits=1, seed=2, progress=False)
    assert not set(CEILING_FIGURES) & set(plain["methods"]["eszsl"]["mean"])
    assert plain["methods"]["eszsl"]["splits"][0]["gzsl_h"] == s["gzsl_h"]
    assert "paired" not in plain  # one method: nothing to pair


def test_printed_table_has_intervals_and_paired_differences(tmp_path, capsys):
    code = main(
        [
            "evaluate",
            *ARGS[:-4],
            "--splits",
            "2",
            "--seed",
            "2",
            "--methods",
            "eszsl,dap",
            "--jobs",
            "1",
            "--rerun-splits",
            "10",
            "--out",
            str(tmp_path / "r.json"),
        ]
    )
    assert code == 0
    captured = capsys.readouterr()
    res = json.loads((tmp_path / "r.json").read_text())
    e = res["methods"]["eszsl"]
    low, high = e["ci95"]["zsl"]
    assert f"{e['mean']['zsl']:.3f} [{low:.3f}, {high:.3f}]" in captured.out
    assert res["rerun_splits"] == 10
    values = [s["zsl"] for s in e["splits"]]
    r_low, r_high = e["rerun95"]["zsl"]
    assert [r_low, r_high] == list(metrics.rerun_interval(values, 10, bounds=(0, 1)))
    assert "where a re-run of 10 splits on another seed lands (95%)" in captured.out
    assert f"[{r_low:.3f}, {r_high:.3f}]" in captured.out
    assert "paired difference from eszsl" in captured.out
    p = res["paired"]["methods"]["dap"]
    assert f"{p['mean']['zsl']:+.3f} [{p['ci95']['zsl'][0]:+.3f}" in captured.out
    # progress: one line per finished split on stderr
    assert "split 1/2 done" in captured.err and "split 2/2 done" in captured.err
    assert "split 1/2 done" not in captured.out


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--jobs", "0"], "expected a positive integer, got 0"),
        (["--jobs", "two"], "expected a positive integer, got 'two'"),
        (["--jobs"], "expected one argument"),
    ],
)
def test_bad_jobs_exit_2_with_a_message(option, message, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", *ARGS, *option])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--jobs" in err and message in err


def test_ceilings_on_raw_trials_exit_2_with_a_message(tmp_path, capsys):
    from tests.framework.raw_data import pilot_path

    for option in (["--ceilings"], ["--rerun-splits", "50"]):
        code = main(
            [
                "evaluate",
                "--dataset",
                f"biotac:{pilot_path()}",
                *option,
                "--out",
                str(tmp_path / "r.json"),
                "--no-progress",
            ]
        )
        assert code == 2
        err = capsys.readouterr().err
        assert "--ceilings, --touches and --rerun-splits apply to known/novel splits" in err
        assert not (tmp_path / "r.json").exists()


def test_evaluate_rejects_bad_jobs():
    ds = simulate_dataset(n_objects=14, seed=0)
    with pytest.raises(ValueError, match="jobs must be a positive integer"):
        evaluate(ds, ["eszsl"], n_novel=3, n_splits=1, progress=False, jobs=0)


def test_report_shows_intervals_paired_differences_and_ceilings(runs):
    from app.evaluation.report import markdown

    res = runs[1]
    md = markdown(res)
    e = res["methods"]["best"]
    low, high = e["ci95"]["ceil_gzsl_h"]
    assert "## Means with their 95 % confidence intervals" in md
    assert f"{e['mean']['ceil_gzsl_h']:.3f} [{low:.3f}, {high:.3f}]" in md
    p = res["paired"]["methods"]["best"]
    lo, hi = p["ci95"]["gzsl_h"]
    cell = f"{p['mean']['gzsl_h']:+.3f} [{lo:+.3f}, {hi:+.3f}] ({p['won']['gzsl_h']} / "
    assert "## Paired differences from `eszsl`" in md and cell in md
    lo, hi = e["rerun95"]["zsl"]
    assert "## Where a re-run lands" in md and f"[{lo:.3f}, {hi:.3f}]" in md
    # results written before intervals existed still make a report, without those sections
    old = {k: v for k, v in res.items() if k != "paired"}
    old["methods"] = {
        m: {k: v for k, v in entry.items() if k not in ("ci95", "rerun95")}
        for m, entry in res["methods"].items()
    }
    assert "95 % confidence" not in markdown(old) and "| `gzsl_h` |" in markdown(old)
    assert "re-run" not in markdown(old)


def test_a_failing_split_in_a_worker_exits_2_with_its_message(tmp_path, capsys):
    """A method that fails inside a worker process fails the command as it does in one
    process: exit 2, the method's own message, no results file."""
    messages = []
    for jobs in ("1", "2"):
        out = tmp_path / f"r{jobs}.json"
        code = main(
            [
                "evaluate",
                *ARGS,
                "--methods",
                "eszsl,best",
                "--param",
                "best.n_estimators=0",
                "--jobs",
                jobs,
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        assert code == 2 and not out.exists()
        err = capsys.readouterr().err
        assert "n_estimators" in err
        messages.append(err)
    assert messages[0] == messages[1]


def test_every_split_gives_its_methods_a_seed_of_its_own(runs):
    # one seed shared by every split would be a random effect no number of splits averages
    # out; each split's methods get their own, the same in every process
    from app.evaluation.protocol import split_method_seed

    res = runs[1]
    seeds = [d["method_seed"] for d in res["methods"]["best"]["details"]]
    assert seeds == [split_method_seed(2, i) for i in range(3)]
    assert len(set(seeds)) == 3 and all(0 <= s < 2**31 for s in seeds)
    assert seeds == [d["method_seed"] for d in res["methods"]["eszsl"]["details"]]  # paired
    assert seeds == [d["method_seed"] for d in runs[2]["methods"]["best"]["details"]]
    assert split_method_seed(3, 0) not in seeds  # another run seed, other method seeds
