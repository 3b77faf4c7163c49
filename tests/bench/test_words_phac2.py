"""bench/words_phac2.py on real PHAC-2 with 2 splits: every figure, a table and a plot."""

import json

import pytest

from bench import words_phac2

pytestmark = pytest.mark.phac2


def test_two_splits_give_agreement_zero_shot_figures_and_a_plot(tmp_path, capsys):
    assert words_phac2.main(["--splits", "2", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "words.json").read_text())
    for kind in ("sentence", "name"):
        a = report["agreement"][kind]
        assert 0.0 <= a["balanced_accuracy"] <= 1.0 and len(a["per_attribute"]) == 19
    assert set(report["summary"]) == set(words_phac2.KINDS)
    assert report["summary"]["vector"]["zsl"]["vs_vector"] == 0.0
    assert 0.0 <= report["summary"]["sentence"]["gzsl_h"]["mean"] <= 1.0
    # estimates fill every attribute a sentence is silent on, and are paired against it
    estimated = report["agreement"]["sentence+estimated"]
    assert estimated["coverage"] > report["agreement"]["sentence"]["coverage"]
    zsl = report["summary"]["sentence+estimated"]["zsl"]
    assert -1.0 <= zsl["vs_sentence"] <= 1.0
    assert "vs_tuned_sentence" in report["summary"]["sentence"]["zsl"]
    assert report["targets"]["zsl_sentence+estimated_over_vector"] == zsl["ratio_to_vector"]
    assert report["descriptions"].endswith("phac2_descriptions_2026-11-28.csv")
    assert (tmp_path / "words.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = capsys.readouterr().out
    assert "| sentence |" in out and "| tuned sentence |" in out
    assert "sentence+estimated against sentence, zsl" in out


def test_bad_arguments_and_a_missing_description_exit_2(tmp_path):
    with pytest.raises(SystemExit) as done:
        words_phac2.main(["--splits", "1"])
    assert done.value.code == 2
    short = tmp_path / "short.csv"
    short.write_text("object_id,name,sentence\n101,car sponge,a soft sponge\n")
    assert words_phac2.main(["--descriptions", str(short), "--out", str(tmp_path)]) == 2


def test_the_development_set_is_read_with_and_without_estimates(capsys):
    from bench import words_development

    assert words_development.main([]) == 0
    report = json.loads(capsys.readouterr().out.split("\n}\n")[0] + "\n}")
    assert 0.5 < report["read"] <= 1.0 and 0.5 < report["read_and_estimated"] <= 1.0
    assert 0.0 < report["coverage_read"] < 1.0
