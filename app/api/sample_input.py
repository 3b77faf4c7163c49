"""One sample from a JSON body: the one converter every route that takes samples uses.

A sample is a nested list of the model's ``input_shape``. Where the model names its
exploratory procedures (``procedures`` of ``GET /v1/models/active``) and the route
answers from some of them (``partial``), a row may be ``null``: a procedure not done
yet, NaN throughout, which the model checks is a whole procedure. The sample may also
come as one entry per procedure, ``[[...47 numbers], null, null, null]`` for PHAC-2's
188 features in 4 procedures (each entry the procedure's block, ``app.data.procedures``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.api.problems import Problem


def sample_array(
    data: list,
    input_shape: tuple[int, ...],
    field: str,
    procedures: tuple[str, ...] = (),
    partial: bool = False,
) -> np.ndarray:
    """``data`` as a float32 array of ``input_shape`` (NaN for a ``null`` row, where
    ``partial``), or a 422 at ``field`` that names the shape expected."""
    expected = f"expected one sample of shape {list(input_shape)}"
    if procedures:
        per = list(_per_procedure(input_shape, procedures))
        expected += f" (or {per}, one entry per procedure)"
    if partial and procedures and any(row is None for row in data):
        data = _nulls_as_nan(data, field)
    elif any(row is None for row in data):
        raise Problem(422, f"{expected}; a row is null, and every value is needed here", field)
    try:
        with np.errstate(over="ignore"):  # beyond float32 is inf: rejected by name later
            x = np.asarray(data, dtype=np.float32)
    except ValueError:  # ragged nesting
        raise Problem(422, f"{expected}; its rows have different lengths", field) from None
    if x.shape == input_shape:
        return x
    if procedures and x.shape == _per_procedure(input_shape, procedures):
        return x.reshape(input_shape)
    raise Problem(422, f"{expected}, got one of shape {list(x.shape)}", field)


def _per_procedure(input_shape: tuple[int, ...], procedures: tuple[str, ...]) -> tuple[int, ...]:
    """The shape of a sample given as one entry per procedure."""
    rows = input_shape[0] // len(procedures)
    return (len(procedures), *((rows,) if rows > 1 else ()), *input_shape[1:])


def _nulls_as_nan(data: list, field: str) -> list[Any]:
    """``data`` with each null row a row of NaN shaped like the sample's other rows."""
    filled = [row for row in data if row is not None]
    if not filled:
        raise Problem(422, "every procedure is missing (null); a sample needs at least one", field)
    try:
        with np.errstate(over="ignore"):  # only the shape is taken here; values are checked later
            nan = np.full(np.shape(np.asarray(filled[0], dtype=np.float32)), np.nan, np.float32)
    except ValueError:
        raise Problem(422, "its rows have different lengths", field) from None
    return [nan if row is None else row for row in data]
