"""The full evaluation protocol on a small simulated dataset, as the method and baseline
tests run it to check that a method beats chance on novel classes."""

from __future__ import annotations

from app.data.simulator import simulate_dataset
from app.evaluation.protocol import evaluate

N_NOVEL = 6  # novel classes per split: chance is 1 / N_NOVEL


def small_protocol(methods: list[str], n_splits: int, method_params: dict) -> dict:
    """``evaluate``'s results for ``methods`` on 30 simulated objects of 6 trials each,
    ``N_NOVEL`` of them novel, one test trial per object, seed 0."""
    ds = simulate_dataset(n_objects=30, trials_per_object=6, seed=0)
    return evaluate(
        ds,
        methods,
        n_novel=N_NOVEL,
        n_splits=n_splits,
        seed=0,
        test_trials=1,
        method_params=method_params,
        progress=False,
    )
