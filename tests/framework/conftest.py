"""Small simulated data and one quickly trained paper model, shared by the framework tests."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.paper import PaperRecognizer

QUICK = dict(encoder_epochs=25, alg1_epochs=80, alg2_epochs=20, fc_z_epochs=80)


@pytest.fixture(scope="session")
def sim_split():
    """36 simulated objects: 30 known (8 training trials, 2 test trials each) and 6 novel."""
    ds = simulate_dataset(n_objects=36, trials_per_object=10, seed=3)
    novel = np.arange(30, 36)
    known = ds.select_classes(np.arange(30))
    trial_no = np.arange(len(known)) % 10  # simulate_dataset orders samples by object, then trial
    return {
        "train": known.subset(trial_no < 8),
        "test": known.subset(trial_no >= 8),
        "novel": ds.select_classes(novel),
    }


@pytest.fixture(scope="session")
def fitted(sim_split) -> PaperRecognizer:
    return PaperRecognizer(seed=0, **QUICK).fit(sim_split["train"])


@pytest.fixture(scope="session")
def with_novel(fitted, sim_split) -> PaperRecognizer:
    novel = sim_split["novel"]
    return fitted.add_novel_classes(novel.class_names, novel.class_attributes)
