"""bench.tables_phac2: development runs refuse the reported seed, and the side-by-side
timing names a real table."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.methods.best import BestRecognizer
from bench import tables_phac2


def test_development_refuses_the_reported_seed(capsys):
    with pytest.raises(SystemExit) as exit_:
        tables_phac2.main(["development", "--seeds", "1,1000"])
    assert exit_.value.code == 2
    assert "seed 1000 is the reported seed" in capsys.readouterr().err


def test_timing_times_a_twelve_object_table_against_twelve_singles():
    ds = simulate_dataset(n_objects=24, trials_per_object=9, seed=1)
    known, novel = ds.select_classes(np.arange(18)), ds.select_classes(np.arange(18, 24))
    model = BestRecognizer(seed=0, n_estimators=10, by_procedure=False).fit(known)
    model = model.add_novel_classes(novel.class_names, novel.class_attributes)
    times = tables_phac2.timing(model, (known.samples,), (novel.samples,), repeats=3)
    assert times["objects"] == 12 and times["repeats"] == 3
    assert times["ratio"] == pytest.approx(times["table_s"] / times["singles_s"])
