"""report.md beside the paper's numbers, and readable, non-empty PNG figures."""

from __future__ import annotations

import json

import matplotlib.image as mpimg
import pytest

from app.evaluation.protocol import evaluate
from app.evaluation.report import PAPER_12, markdown, write_report, write_report_from_file


@pytest.fixture()
def results(oracle):
    return evaluate(
        oracle,
        ["oracle"],
        n_novel=6,
        n_splits=2,
        seed=0,
        test_trials=1,
        progress=False,
        dataset_label="simulated:16",
    )


def test_report_files(results, tmp_path):
    files = write_report(results, tmp_path / "rep")
    names = sorted(p.name for p in files)
    assert names == [
        "fig7_novelty_oracle.png",
        "fig8_confusion_oracle.png",
        "fig8d_jaccard.png",
        "report.md",
    ]
    for p in files:
        data = p.read_bytes()
        assert len(data) > 1000, p
        if p.suffix == ".png":
            assert data[:8] == b"\x89PNG\r\n\x1a\n"
            img = mpimg.imread(p)
            assert img.shape[0] > 200 and img.shape[1] > 200
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "| figure | published paper | oracle |" in md
    assert "| `known_acc` | 0.952 | 1.000 ± 0.000 |" in md
    assert "| `zsl_wrong` | — |" in md  # the method's extra ZSL variant is reported too
    assert "| `osl` | 0.440 |" in md and "| `nd_novel_detected` | 0.895 |" in md
    assert "![Fig. 8d: attribute similarity of the novel objects](fig8d_jaccard.png)" in md


def test_report_from_saved_results(results, tmp_path):
    path = tmp_path / "results.json"
    path.write_text(json.dumps(results))
    files = write_report_from_file(path, tmp_path / "again")
    assert (tmp_path / "again" / "report.md").read_text() == files[0].read_text()
    assert len(files) == 4


def test_twelve_novel_compares_with_table_ix(results):
    twelve = dict(results, novel=12)
    md = markdown(twelve)
    assert PAPER_12["zsl_genf"] == pytest.approx(0.1486, abs=1e-4)
    assert PAPER_12["zsl"] == pytest.approx(0.1657, abs=1e-4)
    assert PAPER_12["osl"] == pytest.approx(0.2914, abs=1e-4)
    assert "| `osl` | 0.291 |" in md and "| `known_acc` | — |" in md


def test_fig8_is_titled_by_the_panels_it_draws(results, tmp_path, monkeypatch):
    from app.evaluation import report

    titles = []
    monkeypatch.setattr(
        report, "plot_confusions", lambda panels, labels, path, title: titles.append(title)
    )
    write_report(results, tmp_path / "rep")
    assert titles == ["Fig. 8: split 1 confusion matrices of ZSL and OSL, oracle"]
    paper = report.confusion_title(["ZSL GEN-F", "ZSL NEIGHB-F", "OSL"], "paper")
    assert (
        paper == "Fig. 8a-c: split 1 confusion matrices of ZSL GEN-F, ZSL NEIGHB-F and OSL, paper"
    )
    assert report.confusion_title(["ZSL"], "m") == "Fig. 8: split 1 confusion matrix of ZSL, m"
