"""bench/scale.py at tiny sizes: every figure of every size, the exponents, the PNG, and
clear refusals of bad arguments. The figures themselves mean nothing at this size."""

from __future__ import annotations

import functools
import json
import subprocess

from tests.bench import ROOT, run_bench

FIELDS = (
    "objects", "fit_s", "fit_peak_gb", "bundle_mb", "enrol_ms", "one_shot_ms", "promote_s",
    "recognise_1_us", "batch_per_sample_us", "batch256_per_sample_us", "throughput_per_s",
    "known_acc", "nn1_acc",
    "zsl_acc", "vectors_distinct", "novel_vectors_taken", "separation", "fit_timings",
    "by_procedure_s", "known_acc_one_procedure",
)  # fmt: skip


run = functools.partial(run_bench, "bench.scale")


def tracked_changes() -> str:
    """Tracked files that differ from HEAD, as ``git status`` lists them."""
    cmd = ["git", "status", "--porcelain", "--untracked-files=no"]
    return subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=ROOT).stdout.strip()


def test_tiny_sizes_give_every_figure_a_table_and_a_plot(tmp_path):
    done = run("--sizes", "12,24,40", "--max", "24", "--novel", "12", "--trials", "4",
               "--separation", "phac2", "--method", "best", "--param", "procedure_estimators=7",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "scale.json").read_text())
    assert [r["objects"] for r in report["sizes"]] == [12, 24]  # --max stops before 40
    for r in report["sizes"]:
        assert set(FIELDS) <= set(r)
        assert r["fit_s"] > 0 and r["fit_peak_gb"] > 0 and r["recognise_1_us"] > 0
        assert r["batch256_per_sample_us"] > 0
        assert 0 < r["promote_s"] < r["fit_s"]
        assert r["separation"] == "phac2"
        assert 0 < r["fit_timings"]["total_s"] <= r["fit_s"]  # the model's own breakdown
        assert r["by_procedure_s"] == r["fit_timings"].get("by_procedure_s")
        assert r["n_jobs"] == 1  # what the service's bootstrap and refit run with
        for acc in ("known_acc", "nn1_acc", "zsl_acc", "known_acc_one_procedure"):
            assert 0.0 <= r[acc] <= 1.0
        assert r["vectors_distinct"] <= r["objects"]
        assert 0 < r["zsl_by_novel"]["10"]["enrolled"] <= 10  # 100 and 1,000: beyond --novel
        assert set(r["zsl_by_novel"]) == {"10"} and 0 <= r["zsl_by_novel"]["10"]["zsl"] <= 1
    assert set(report["exponents"]) >= {"fit_s", "fit_peak_gb", "recognise_1_us"}
    assert report["machine"]["cpus"] >= 1 and report["machine"]["commit"]
    stamp = report["machine"]  # the tree's changes beside the commit
    assert stamp["dirty"] == bool(stamp["changed"]) == bool(tracked_changes())
    assert report["separation"] == "phac2"
    assert (report["novel"], report["trials"], report["seed"]) == (12, 4, 0)  # what made it
    assert report["params"] == {"procedure_estimators": 7}  # the value read as JSON
    assert done.stdout.startswith("| objects | fit_s |") and "| exponent |" in done.stdout
    assert "| by_procedure_s |" in done.stdout.splitlines()[0]
    assert (tmp_path / "scale.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_another_method_with_contact_modes_beside_the_lda_reference(tmp_path):
    done = run("--sizes", "16", "--novel", "6", "--trials", "4", "--modes", "2",
               "--method", "prototypes", "--param", "n_jobs=2", "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "scale.json").read_text())
    assert report["method"] == "prototypes" and report["modes"] == 2
    (r,) = report["sizes"]
    assert r["method"] == "prototypes" and r["modes"] == 2 and r["n_jobs"] == 2
    for key in ("known_acc", "lda_acc", "nd_auroc", "lda_auroc", "nd_known_kept"):
        assert 0.0 <= r[key] <= 1.0, key
    # the kernel's high-water mark of the fit, apart from the simulator's before it
    assert 0 < r["fit_peak_gb"] and 0 < r["simulator_peak_gb"]
    assert "| lda_acc |" in done.stdout.splitlines()[0]


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--sizes", "1,10"), "at least 2 objects"),
        (("--sizes", "ten"), "--sizes must be integers"),
        (("--sizes", "60,300", "--max", "10"), "below the smallest size"),
        (("--trials", "3"), "--trials at least 4"),
        (("--separation", "far"), "--separation takes none or phac2"),
        (("--param", "trees"), "--param expects NAME=VALUE"),
        (("--method", "forest"), "--method takes one of"),
        (("--modes", "0"), "--modes must be at least 1"),
    ):
        done = run(*args, "--out", str(tmp_path))
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
