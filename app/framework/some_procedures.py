"""Answers from some procedures: samples that lack some exploratory procedures (NaN
throughout their blocks) are answered from those they hold, by models that
``answers_from_some_procedures``, and each answer names the procedure to do next until it is
confident (``TARGET_CONFIDENCE``) and used at least ``MIN_PROCEDURES``.

``by_procedures`` runs a part of a model on each group of rows that hold the same
procedures; ``asks_next`` says which answers should ask for another procedure.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

#: ``next_procedure`` says stop (None) once the answer's probability reaches the target
#: confidence, this by default, and at least ``MIN_PROCEDURES`` procedures were done.
#: Chosen on PHAC-2's development splits (seeds 1-2, 10 splits,
#: ``bench/research/explore_stopping.py``, each procedure chosen by gain per second): at
#: 0.4 the rule used 0.39 of the robot time, known-object accuracy -0.009 and ``gzsl_h``
#: +0.001 from all procedures; at 0.3, 0.33 of the time and ``gzsl_h`` +0.008; at 0.5,
#: 0.51 of the time, known-object accuracy -0.007.
TARGET_CONFIDENCE = 0.4
#: One procedure alone answers confidently and wrongly too often: on the same splits,
#: stopping at the first confident answer lost 0.059-0.067 of known-object accuracy at
#: targets 0.3 to 0.5 (move down first) and 0.017-0.023 with squeeze first; a second
#: procedure before stopping lost 0.003-0.009.
MIN_PROCEDURES = 2


def by_procedures(
    x: np.ndarray, used: np.ndarray, part: Callable[[np.ndarray, np.ndarray], Any]
) -> Any:
    """``part(rows, keep)`` on each group of rows that hold the same procedures ``keep``
    (indices), put back in row order. ``part`` returns an array or a tuple of arrays
    (a None entry stays None)."""
    patterns, which = np.unique(used, axis=0, return_inverse=True)
    which = which.ravel()
    out: list[np.ndarray | None] = []
    single = False
    for g, pattern in enumerate(patterns):
        rows = np.flatnonzero(which == g)
        got = part(x[rows], np.flatnonzero(pattern))
        single = not isinstance(got, tuple)
        parts = (got,) if single else got
        if not out:
            out = [None if a is None else np.empty((len(x), *a.shape[1:]), a.dtype) for a in parts]
        for o, a in zip(out, parts, strict=True):
            if o is not None:
                o[rows] = a
    return out[0] if single else tuple(out)


def asks_next(
    top_probability: np.ndarray, used: np.ndarray, target_confidence: float
) -> np.ndarray:
    """(N,) bool: the answers that should ask for another procedure: their top probability
    (``top_probability``, (N,)) is below ``target_confidence`` or they used fewer than
    ``MIN_PROCEDURES`` procedures (``used``, (N, P) bool), and some procedure is left."""
    unsure = top_probability < float(target_confidence)
    return (unsure | (used.sum(axis=1) < MIN_PROCEDURES)) & ~used.all(axis=1)
