"""bench/leaf_trees.py at a tiny size: both growers timed, their ratio printed, and bad
arguments refused with exit 2."""

from __future__ import annotations

import re

import pytest

from bench import leaf_trees


def test_it_times_both_growers_and_prints_their_ratio(capsys):
    assert leaf_trees.main(["--trees", "20", "--samples", "6", "--features", "40"]) == 0
    out = capsys.readouterr().out
    assert float(re.search(r"leaf_trees: (\S+) us a tree", out).group(1)) > 0
    assert float(re.search(r"scikit-learn: (\S+) us a tree", out).group(1)) > 0
    assert float(re.search(r"scikit-learn / leaf_trees: (\S+)x", out).group(1)) > 0


def test_bad_arguments_exit_2():
    with pytest.raises(SystemExit) as exc:
        leaf_trees.main(["--samples", "1"])
    assert exc.value.code == 2
