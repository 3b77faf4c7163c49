"""Small synthetic raw BioTac datasets whose objects differ by construction, and the real
pilot's folder (skipped, with the reason, where it is absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.data.biotac import BioTacDataset, RawTrial, pressure_from_group
from tests.data.biotac_samples import finger_data

PRESSURES = (100, 150, 200)
BIOTAC_PILOT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "biotac_pilot"


def object_trial(k: int, seed: int) -> RawTrial:
    """A trial of object ``k``: two fingers pressing 150 + 120 k counts, its electrodes and
    temperatures shifted by an amount of its own, with sensor noise of its own seed."""
    fingers = []
    for f in range(2):
        d = finger_data(seed=1000 * seed + f, rise=150.0 + 120.0 * k)
        d["electrodes"] = d["electrodes"] + 40.0 * k * np.sin(np.arange(19) + k)
        d["tdc"] = d["tdc"] + 15.0 * k
        fingers.append(d)
    return RawTrial(fingers=tuple(fingers))


def synthetic_biotac(
    n_objects: int = 3, trials_per_object: int = 6, attributes: np.ndarray | None = None
) -> BioTacDataset:
    """``n_objects`` objects of ``trials_per_object`` trials each, named like the pilot's
    groups (``obj<k>_pdc<P>_1cm_<NN>``, pressures cycling through 100, 150, 200);
    ``attributes``: an optional (K, M) matrix (M = 0 without)."""
    trials, labels, groups = [], [], []
    for k in range(n_objects):
        for n in range(trials_per_object):
            trials.append(object_trial(k, seed=k * 100 + n))
            labels.append(k)
            groups.append(f"obj{k}.h5/obj{k}_pdc{PRESSURES[n % 3]}_1cm_{n + 1:02d}")
    names = tuple(f"obj{k}" for k in range(n_objects))
    attrs = np.zeros((n_objects, 0), np.float32) if attributes is None else attributes
    return BioTacDataset(
        trials=tuple(trials),
        labels=np.array(labels),
        trial_ids=np.arange(len(trials)),
        class_names=names,
        attribute_names=tuple(f"a{j}" for j in range(attrs.shape[1])),
        attribute_values=attrs,
        groups=tuple(groups),
        grip_pressure=np.array([pressure_from_group(g) for g in groups]),
    )


def pilot_path() -> Path:
    if not (BIOTAC_PILOT / "cork.h5").is_file():
        pytest.skip(f"BioTac pilot data not found at {BIOTAC_PILOT.resolve()}")
    return BIOTAC_PILOT
