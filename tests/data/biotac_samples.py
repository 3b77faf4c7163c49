"""Synthetic raw BioTac trials whose phases and signals are known by construction."""

from __future__ import annotations

import numpy as np

from app.data.biotac import RawTrial

REST = 800.0
CONTACTS = ((150, 170), (300, 500), (600, 660))  # tap, hold, squeeze: [start, end) frames


def finger_data(
    n_frames: int = 800, contacts=CONTACTS, rest: float = REST, rise: float = 200.0, seed: int = 0
) -> dict[str, np.ndarray]:
    """One finger: pdc at ``rest`` with a plateau ``rise`` counts higher in each contact,
    the other channels random integers like raw 12-bit counts."""
    rng = np.random.default_rng(seed)
    pdc = np.full(n_frames, rest)
    for s, e in contacts:
        pdc[s:e] += rise
    return {
        "pdc": pdc,
        "tdc": rng.integers(2000, 2100, n_frames).astype(float),
        "tac": rng.integers(1900, 2100, n_frames).astype(float),
        "pac": rng.integers(1900, 2100, (n_frames, 22)).astype(float),
        "electrodes": rng.integers(2500, 3500, (n_frames, 19)).astype(float),
    }


def trial_data(n_fingers: int = 2, seed: int = 0, **kwargs) -> dict[str, list]:
    """The JSON form of a trial, as it would arrive over HTTP."""
    return {
        "fingers": [
            {k: v.tolist() for k, v in finger_data(seed=seed + f, **kwargs).items()}
            for f in range(n_fingers)
        ]
    }


def synthetic_trial(n_fingers: int = 2, seed: int = 0, **kwargs) -> RawTrial:
    return RawTrial(fingers=tuple(finger_data(seed=seed + f, **kwargs) for f in range(n_fingers)))
