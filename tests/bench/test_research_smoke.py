"""Every script of bench/research still runs against today's app/ and prints its kind of report.

The scripts are experiments that docs/RESULTS.md cites for its figures and decisions.
Nothing in the product runs them, so this runs each one at ``--tiny`` size (one split of
one seed, costly loops cut short: a few seconds each) in a subprocess, as the documented
commands do, and checks the shape of what it prints. The figures themselves mean nothing
at that size and are not checked.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import runpy
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RESEARCH = ROOT / "bench" / "research"
HELPERS = {"dev_splits.py"}  # imported by the scripts, never run on its own
FIGURES = ("known_acc", "nd_auroc", "zsl", "osl", "gzsl_h")


def run(script: str, phac2: Path, *args: str) -> subprocess.CompletedProcess:
    """``script --tiny --data phac2 args`` with the test's own (the venv's) Python."""
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")  # a smoke run on a shared machine: one BLAS thread
    done = subprocess.run(
        [sys.executable, str(RESEARCH / script), "--tiny", "--data", str(phac2), *args],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
        cwd=ROOT,
    )
    assert done.returncode == 0, f"{script} exited {done.returncode}:\n{done.stderr[-4000:]}"
    return done


def share(value: object) -> bool:
    """A figure that is a share (accuracy, AUROC, balance): a number in [0, 1]."""
    return isinstance(value, float | int) and not math.isnan(value) and 0 <= value <= 1


def check_zsl_means(report: dict, keys: list[str]) -> None:
    """dev_splits.print_zsl_means's report: one split, each key's mean a share."""
    assert report["splits_run"] == 1
    assert set(keys) <= set(report["zsl_mean"]), sorted(report["zsl_mean"])
    assert all(share(report["zsl_mean"][k]) for k in keys), report["zsl_mean"]


def novelty_bound(phac2: Path, tmp: Path) -> None:
    lines = run("novelty_bound.py", phac2, "--seeds", "1").stdout.splitlines()
    rows = [line.split() for line in lines if re.match(r"\s*\d+\s+\d+\s", line)]
    assert len(rows) == 1, lines  # seed 1, split 1
    mean = lines[-1].split()
    assert mean[0] == "mean" and all(share(float(v)) for v in mean[1:4]), lines


def explore_routing(phac2: Path, tmp: Path) -> None:
    report = json.loads(run("explore_routing.py", phac2, "--temperatures", "0,0.1").stdout)
    assert set(report["by_temperature"]) == {"0.0", "0.1"}
    for figures in report["by_temperature"].values():
        assert set(figures) == {"gzsl_seen", "gzsl_unseen", "gzsl_h"}
        assert all(share(v) for v in figures.values()), figures


def explore_stopping(phac2: Path, tmp: Path) -> None:
    report = json.loads(run("explore_stopping.py", phac2, "--targets", "0.5").stdout)
    assert report["splits_run"] == 1
    assert set(report["rules"]) == {"all"} | {
        f"{r}@0.5" for r in ("top", "two", "agree", "top_per_second", "two_per_second")
    }
    for figures in report["rules"].values():
        assert share(figures["known_acc"]) and share(figures["gzsl_h"]), figures
        assert 0 < figures["time"] <= 1, figures
    assert report["rules"]["all"]["time"] == 1.0


def explore_best(phac2: Path, tmp: Path) -> None:
    variants = ["best", "best:n_estimators=10"]
    out = tmp / "runs.json"
    table = run("explore_best.py", phac2, "--variants", ";".join(variants), "--out", str(out))
    rows = [line for line in table.stdout.splitlines() if line.startswith("best")]
    assert [r.split()[0] for r in rows] == variants, table.stdout
    runs = json.loads(out.read_text())
    assert [(r["variant"], r["seed"]) for r in runs] == [(v, 1) for v in variants]
    for r in runs:
        mean = r["results"]["methods"]["best"]["mean"]
        assert all(share(mean[f]) for f in FIGURES), mean


def explore_zsl(phac2: Path, tmp: Path) -> None:
    report = json.loads(run("explore_zsl.py", phac2, "--approaches", "fclswgan,eszsl").stdout)
    check_zsl_means(report, ["dap", "fclswgan", "dap*fclswgan", "eszsl", "dap*eszsl"])


def explore_fingers(phac2: Path, tmp: Path) -> None:
    approaches = ["plain", "swap", "swap-train", "sym", "mean"]
    report = json.loads(run("explore_fingers.py", phac2).stdout)
    check_zsl_means(
        report,
        ["dap", *approaches, *(f"dap*{a}" for a in approaches), *(f"auc_{a}" for a in approaches)],
    )


def explore_scorespace(phac2: Path, tmp: Path) -> None:
    # one of each family of approaches the docstring lists, and a sum of two
    combos = (
        "asg,asg-diag,flg,twins1,svm1,znorm,lda0.1,saes400,saef1,ksae100@1,bag2,"
        "dap-C0.3,dap-fisher,ep-dap,ep-sae,saes400+bag2"
    ).split(",")
    report = json.loads(
        run("explore_scorespace.py", phac2, "--approaches", ",".join(combos)).stdout
    )
    check_zsl_means(report, ["dap", *combos, *(f"dap*{c}" for c in combos)])


def explore_cadavae(phac2: Path, tmp: Path) -> None:
    out = tmp / "cadavae.json"
    done = run(
        "explore_cadavae.py",
        phac2,
        "--check-best",
        "--variants",
        "base;latent=8",
        "--out",
        str(out),
    )
    gap = re.search(r"check-best: max \|p_dap - best.novel_proba\| = (\S+)", done.stderr)
    assert gap and float(gap.group(1)) < 1e-6, done.stderr[-2000:]  # its DAP is best's
    report = json.loads(done.stdout)
    assert report["protocol"] == "test" and report["splits"] == 1
    assert set(report["variants"]) == {"base", "latent=8"}
    for variant in report["variants"].values():
        assert all(share(variant[k]["mean"]) for k in ("cada", "cada*dap", "dap")), variant
    assert {len(rows) for rows in json.loads(out.read_text())["rows"].values()} == {1}
    # the validation protocol: objects carved from the known ones, nothing of the novel ones
    val = json.loads(run("explore_cadavae.py", phac2, "--protocol", "val").stdout)
    assert val["protocol"] == "val" and share(val["variants"]["base"]["cada"]["mean"])


def explore_attributes(phac2: Path, tmp: Path) -> None:
    done = run("explore_attributes.py", phac2, "--space", "ep", "--verify")
    verified = [json.loads(line) for line in done.stderr.splitlines() if '"verify_seed"' in line]
    assert verified and verified[0]["max_abs_diff"] < 1e-6 and verified[0]["same_argmax"]
    report = json.loads(done.stdout)
    assert report["n_splits_run"] == 1 and report["combos"] == 15  # the 15 EP subsets at C 0.1
    for variant in ("dap", "sel", "sel_auc", "zacc", "ens3", "prior"):
        assert share(report["zsl_mean"][variant]), report["zsl_mean"]
    assert set(report["per_attribute"]) >= {"hard", "smooth", "metallic"}


def explore_novelty(phac2: Path, tmp: Path) -> None:
    cues = ["phases", "proximity", "mahalanobis", "prototype", "attributes", "attributes-any"]
    done = run("explore_novelty.py", phac2, "--cues", ",".join(cues), "--weights", "0.02")
    means = done.stdout.split("mean over splits")[1]
    figures = dict(re.findall(r"^\s+(\S+)\s+([\d.]+ / [\d.]+)$", means, re.MULTILINE))
    assert set(figures) == {"best", *cues, *(f"best+{c}*0.02" for c in cues)}, means
    for pair in figures.values():
        assert all(share(float(v)) for v in pair.split(" / ")), pair


def attribute_growth(phac2: Path, tmp: Path) -> None:
    out, png = tmp / "growth.json", tmp / "growth.png"
    done = run("attribute_growth.py", phac2, "--out", str(out), "--plot", str(png))
    assert done.stdout.startswith("| attribute |") and png.stat().st_size > 0, done.stdout
    report = json.loads(out.read_text())
    assert report["splits_run"] == 1 and report["attributes"] == ["hard", "smooth"]
    for figures in report["per_attribute"].values():
        for condition in ("start", "later"):
            auc, zsl = figures[condition]["mean"]["auc"], figures[condition]["mean"]["zsl"]
            assert (auc is None or share(auc)) and share(zsl), figures  # None: AUC skipped


def rerun_check(phac2: Path, tmp: Path) -> None:
    from app.cli import main

    base, out, png = tmp / "base.json", tmp / "check.json", tmp / "check.png"
    args = ["--dataset", f"phac2:{phac2}", "--novel", "6", "--splits", "2", "--seed", "5"]
    code = main(["evaluate", *args, "--methods", "best", "--jobs", "1", "--out", str(base)])
    assert code == 0
    done = run(
        "rerun_check.py",
        phac2,
        *("--base", str(base), "--base", str(base), "--seeds", "9,10"),
        *("--out", str(out), "--plot", str(png)),
    )
    assert done.stdout.startswith("`best`, 6 novel objects: published over 2 splits (seed 5)")
    assert png.stat().st_size > 0 and (tmp / "check-2.png").stat().st_size > 0
    first, second = json.loads(out.read_text())
    assert first == second  # the same base twice: the same re-runs, the same counts
    assert first["seeds"] == [9] and first["rerun_splits"] == 1  # --tiny: one seed, one split
    for row in first["methods"]["best"].values():
        assert row["checked"] == 1 and row["inside_rerun95"] in (0, 1)
        assert share(row["reruns"]["9"]) and share(row["base_mean"])


def small_catalogue(phac2: Path, tmp: Path) -> None:
    report = json.loads(run("small_catalogue.py", phac2).stdout)
    assert report["seeds"] == [101] and set(report["accuracy"]) == {
        "phac2 K=2",
        "simulator K=2",
    }
    for figures in report["accuracy"].values():
        assert set(figures) == {"best", "prototypes"}
        assert all(share(f["mean"]) for f in figures.values()), figures


SCRIPTS: dict[str, Callable[[Path, Path], None]] = {
    f"{check.__name__}.py": check
    for check in (
        novelty_bound,
        explore_routing,
        explore_stopping,
        explore_best,
        explore_zsl,
        explore_fingers,
        explore_scorespace,
        explore_cadavae,
        explore_attributes,
        explore_novelty,
        attribute_growth,
        rerun_check,
        small_catalogue,
    )
}


def test_every_research_script_has_a_smoke_run() -> None:
    present = {p.name for p in RESEARCH.glob("*.py")} - HELPERS
    assert present == set(SCRIPTS), "add a smoke run for each new script (or drop a removed one)"


def test_tiny_is_one_split_of_the_first_seed() -> None:
    dev_splits = runpy.run_path(str(RESEARCH / "dev_splits.py"))
    parser = argparse.ArgumentParser()
    dev_splits["add_split_arguments"](parser)
    args = dev_splits["tiny"](parser.parse_args(["--tiny", "--seeds", "2,1"]), epochs=3)
    assert (args.seeds, args.splits, args.epochs) == ("2", 1, 3)
    full = dev_splits["tiny"](parser.parse_args(["--seeds", "1,2"]), epochs=3)
    assert (full.seeds, full.splits, hasattr(full, "epochs")) == ("1,2", 7, False)
    with pytest.raises(SystemExit, match="seed 0"):
        dev_splits["split_seeds"](parser.parse_args(["--seeds", "0"]), development_only=True)


@pytest.mark.phac2
@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_research_script_runs_at_tiny_size(script: str, phac2_path: Path, tmp_path: Path) -> None:
    SCRIPTS[script](phac2_path.resolve(), tmp_path)
