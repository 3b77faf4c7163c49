"""Progress bars appear on a terminal only: a service's log, or a run whose stderr goes to a
file, gets none of their redraws."""

from __future__ import annotations

import io
import sys

import pytest

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method

FAST = {"n_estimators": 10, "tuning_rounds": 1, "distance_components": 4}


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(scope="module")
def dataset():
    return simulate_dataset(n_objects=8, trials_per_object=4, seed=0)


@pytest.mark.parametrize("stderr, drawn", [(io.StringIO, False), (Terminal, True)])
def test_a_fit_draws_its_bar_on_a_terminal_only(dataset, monkeypatch, stderr, drawn):
    err = stderr()
    monkeypatch.setattr(sys, "stderr", err)
    make_method("best", **FAST).fit(dataset, progress=True)
    assert ("best on" in err.getvalue()) is drawn, err.getvalue()


def test_no_progress_hides_the_bar_on_a_terminal_too(dataset, monkeypatch):
    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    make_method("best", **FAST).fit(dataset, progress=False)
    assert err.getvalue() == ""
