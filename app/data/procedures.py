"""Exploratory procedures inside a sample: which rows hold which procedure, which are there.

A robot explores an object by procedures (PHAC-2: squeeze, hold, slide, move down), and a
sample holds them in order along its first axis: with P procedures that axis splits into
P equal blocks, one per procedure (PHAC-2's flat 188 features are 4 blocks of 47; the
simulator's 32 x 30 image is 4 blocks of 8 rows). A procedure the robot has not done yet
is missing: its whole block is NaN. A block that is only partly NaN is an error, and so
is a sample with no procedure at all.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: Seconds of robot time per procedure, by the names the datasets give them. PHAC-2's
#: robot controller (IanTheEngineer/Penn-haptics-bolt, gripper_controller.cpp) holds for
#: 10 s, slides 5 cm in 5 s (SLIDE_5CM) and 5 cm in 2 s (MOVE_DOWN_5CM); its squeeze runs
#: until a set pressure, with no fixed time: 4.2 s is the median squeeze contact of the
#: BioTac pilot's 74 trials, recorded by the same controller. The simulator's four take
#: PHAC-2's times. Raw BioTac trials' phases: tap 0.23 s, squeeze 4.2 s, the pilot's
#: median contacts (``python -m bench.phase_seconds``); their hold shares the simulator's
#: name and 10 s, where the pilot's hold lasts 16.93 s (give ``--durations hold=16.93`` to
#: measure the pilot's robot time).
SECONDS: dict[str, float] = {
    "SQUEEZE_SET_PRESSURE_SLOW": 4.2,
    "HOLD_FOR_10_SECONDS": 10.0,
    "SLIDE_5CM": 5.0,
    "MOVE_DOWN_5CM": 2.0,
    "squeeze": 4.2,
    "hold": 10.0,
    "slide": 5.0,
    "move_down": 2.0,
    "tap": 0.23,
}


def seconds_of(procedures: Sequence[str]) -> np.ndarray:
    """(P,) robot seconds of each procedure from ``SECONDS``; a name it lacks costs the
    mean of those it has (1 s each when it has none), so unknown procedures weigh alike."""
    known = [SECONDS[p] for p in procedures if p in SECONDS]
    fill = float(np.mean(known)) if known else 1.0
    return np.array([SECONDS.get(p, fill) for p in procedures], np.float64)


class ProcedureError(ValueError):
    """Procedure names that do not fit the samples, or a sample whose procedures are
    partly missing or all missing. ``sample`` and ``procedure`` name the culprit where
    there is one."""

    def __init__(self, message: str, sample: int | None = None, procedure: str | None = None):
        super().__init__(message)
        self.sample, self.procedure = sample, procedure


def check_procedures(procedures: Sequence[str], input_shape: tuple[int, ...]) -> None:
    """ProcedureError unless the names are distinct, non-empty and split the samples' first
    axis into equal blocks."""
    names = list(procedures)
    if not names:
        raise ProcedureError("give at least one procedure name")
    blank = [i for i, n in enumerate(names) if not str(n).strip()]
    if blank:
        raise ProcedureError(f"procedure {blank[0] + 1} has an empty name")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ProcedureError(f"procedure names must be distinct; repeated: {', '.join(repeated)}")
    if not input_shape or input_shape[0] % len(names):
        first = input_shape[0] if input_shape else 0
        raise ProcedureError(
            f"{len(names)} procedures do not split a sample's first axis of {first} into "
            "equal blocks"
        )


def block(procedures: Sequence[str], input_shape: tuple[int, ...], j: int) -> slice:
    """The rows of a sample's first axis that hold procedure ``j``."""
    size = input_shape[0] // len(procedures)
    return slice(j * size, (j + 1) * size)


def present(x: np.ndarray, procedures: Sequence[str]) -> np.ndarray:
    """(N, P) bool: which procedures each sample of ``x`` ((N, *input_shape)) holds.

    ProcedureError for a sample that holds none, or one whose procedure is partly NaN."""
    n, p = len(x), len(procedures)
    blocks = np.isnan(x.reshape(n, p, -1))
    missing = blocks.all(axis=2)
    partly = blocks.any(axis=2) & ~missing
    if partly.any():
        i, j = np.argwhere(partly)[0]
        rows = block(procedures, x.shape[1:], int(j))
        cell = first_nan(x[i], rows)
        raise ProcedureError(
            f"sample {i}: procedure '{procedures[j]}' is partly missing: cell "
            f"{cell_name(int(i), cell)} is NaN where the procedure's other values are numbers; "
            "send all of its values, or none (a missing procedure is null or NaN throughout)",
            int(i),
            procedures[j],
        )
    empty = missing.all(axis=1)
    if empty.any():
        i = int(empty.argmax())
        raise ProcedureError(
            f"sample {i}: every procedure is missing; a sample needs at least one of "
            f"{', '.join(procedures)}",
            i,
        )
    return ~missing


def first_nan(sample: np.ndarray, rows: slice = slice(None)) -> tuple[int, ...]:
    """The index in ``sample`` of its first NaN (or infinity) within ``rows``."""
    bad = ~np.isfinite(sample[rows])
    first = np.unravel_index(int(bad.argmax()), bad.shape)
    return (int(first[0]) + (rows.start or 0), *map(int, first[1:]))


def named_list(names: Sequence[str], noun: str) -> str:
    """``procedure 'hold'``, ``procedures 'hold' and 'slide'``, ``procedures 'a', 'b' and 'c'``."""
    quoted = [f"'{n}'" for n in names]
    if len(quoted) == 1:
        return f"{noun} {quoted[0]}"
    return f"{noun}s {', '.join(quoted[:-1])} and {quoted[-1]}"


def cell_name(i: int, cell: tuple[int, ...]) -> str:
    """``[0][3][4]``: cell (3, 4) of sample 0, as a JSON body's ``samples`` nests it."""
    return "".join(f"[{k}]" for k in (i, *cell))


def keep_only(x: np.ndarray, procedures: Sequence[str], keep: Sequence[int]) -> np.ndarray:
    """A copy of samples ``x`` with every procedure outside ``keep`` (indices) missing."""
    out = np.array(x, dtype=np.float32, copy=True)
    shape = out.shape[1:]
    for j in range(len(procedures)):
        if j not in keep:
            out[:, block(procedures, shape, j)] = np.nan
    return out
