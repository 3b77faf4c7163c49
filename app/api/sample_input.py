"""One sample from a JSON body: the one converter every route that takes samples uses.

A sample is a nested list of the model's ``input_shape``. Where the model names its
exploratory procedures (``procedures`` of ``GET /v1/models/active``) and the route
answers from some of them (``partial``), a row may be ``null``: a procedure not done
yet, NaN throughout, which the model checks is a whole procedure. The sample may also
come as one entry per procedure, ``[[...47 numbers], null, null, null]`` for PHAC-2's
188 features in 4 procedures (each entry the procedure's block, ``app.data.procedures``).
A row (or entry) with no number in it, ``null`` or NaN in every cell, is a ``null`` row:
orjson and JavaScript's ``JSON.stringify`` write NaN as ``null``, so a client that marks a
procedure not done with NaN sends rows of ``null`` cells (``missing_as_null``). A row with
some numbers and some ``null`` cells stays a 422 that names it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.api.problems import Problem
from app.data.procedures import block, named_list


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
    if partial:  # elsewhere NaN rows stay NaN, for the model to name the procedures missing
        data = missing_as_null(data)
    if procedures:
        per = list(_per_procedure(input_shape, procedures))
        expected += f" (or {per}, one entry per procedure)"
    if partial and procedures and any(row is None for row in data):
        data = _nulls_as_nan(data, field)
    elif any(row is None for row in data):
        raise Problem(
            422, f"{field}: {expected}; a row is null, and every value is needed here", field
        )
    try:
        with np.errstate(over="ignore"):  # beyond float32 is inf: rejected by name later
            x = np.asarray(data, dtype=np.float32)
    except ValueError:  # ragged nesting
        raise Problem(422, f"{field}: {expected}; its rows have different lengths", field) from None
    if x.shape == input_shape:
        return x
    if procedures and x.shape == _per_procedure(input_shape, procedures):
        return x.reshape(input_shape)
    raise Problem(422, f"{field}: {expected}, {_got(x.shape, input_shape, procedures)}", field)


def missing_as_null(sample: Any) -> Any:
    """``sample`` with each row (or per-procedure entry) that holds no number, ``null`` or
    NaN in every cell, as ``null``: a procedure not done. Anything else comes back as it
    came, for the validators to name. A pydantic before-validator of the sample types."""
    if not isinstance(sample, list) or not any(_no_number(row) for row in sample):
        return sample
    return [None if _no_number(row) else row for row in sample]


def _no_number(row: Any) -> bool:
    """Whether ``row`` is a non-empty list whose every cell, at any depth, is null or NaN.
    A row of numbers stops at its first cell."""
    if not isinstance(row, list) or not row:
        return False
    return all(_no_number(v) if isinstance(v, list) else _no_value(v) for v in row)


def _no_value(cell: Any) -> bool:
    return cell is None or (isinstance(cell, float) and math.isnan(cell))


def sample_shapes(input_shape: tuple[int, ...], procedures: tuple[str, ...] = ()) -> set:
    """The shapes one sample may come in: ``input_shape``, or one entry per procedure."""
    return {tuple(input_shape)} | (
        {_per_procedure(input_shape, procedures)} if procedures else set()
    )


def nested_shape(value: Any) -> tuple[int, ...]:
    """The shape of nested lists, read along the first entry that is not null at each level
    (a sample's null rows are procedures not done)."""
    shape = []
    while isinstance(value, list):
        shape.append(len(value))
        value = next((v for v in value if v is not None), None)
    return tuple(shape)


def is_one_sample(value: Any, input_shape: tuple[int, ...], procedures: tuple[str, ...]) -> bool:
    """Whether ``value``, given where a list of samples belongs, is one sample alone (of
    ``input_shape``, or one entry per procedure) and not a list of samples. No list of
    samples has a sample's shape: its entries would be samples' rows."""
    taken = sample_shapes(input_shape, procedures)
    first = next((v for v in value if v is not None), None) if isinstance(value, list) else None
    return nested_shape(value) in taken and nested_shape(first) not in taken


def _got(shape: tuple[int, ...], input_shape: tuple[int, ...], procedures: tuple[str, ...]) -> str:
    """What came instead of one sample, and the likely fix."""
    if shape[1:] in sample_shapes(input_shape, procedures):
        if shape[0] == 1:
            return "got a list holding one: send the sample without its outer list"
        return f"got a list of {shape[0]}: send them one at a time"
    return f"got one of shape {list(shape)}"


def explain(
    body: Any, input_shape: tuple[int, ...], procedures: tuple[str, ...], partial: bool
) -> list[dict[str, str]]:
    """What is wrong with the samples of a request body that failed validation, by shape,
    where that says more than the value a validator stopped at: one sample where a list
    of them belongs, a list where one belongs, or null rows where whole samples are needed
    (``partial``: the route answers from some procedures). Empty where shape is not it."""
    if not isinstance(body, dict):
        return []
    taken = sample_shapes(input_shape, procedures)
    expected = f"one sample of shape {list(input_shape)}"
    found = []
    one = body.get("sample")
    if isinstance(one, list):
        if nested_shape(one)[1:] in taken:
            found.append(
                (
                    "sample",
                    f"expected {expected}, {_got(nested_shape(one), input_shape, procedures)}",
                )
            )
        elif not partial:
            found.append(("sample", _nulls(one, input_shape, procedures)))
    many = body.get("samples")
    if isinstance(many, list) and not partial:  # routes with partial samples take one alone
        if is_one_sample(many, input_shape, procedures):
            found.append(
                (
                    "samples",
                    f"expected a list of samples, got {expected} alone: wrap one sample in a list",
                )
            )
        else:
            found.extend(
                (f"samples[{i}]", _nulls(x, input_shape, procedures)) for i, x in enumerate(many)
            )
    return [{"field": f, "reason": r} for f, r in found if r]


def _nulls(sample: Any, input_shape: tuple[int, ...], procedures: tuple[str, ...]) -> str:
    """Why a sample with null rows is refused where whole samples are needed: the
    procedures they leave out, or the rows. Empty where no row is null."""
    sample = missing_as_null(sample)
    if not isinstance(sample, list) or not any(row is None for row in sample):
        return ""
    nulls = [i for i, row in enumerate(sample) if row is None]
    if procedures and len(sample) == len(procedures) and nested_shape(sample) != input_shape:
        missing = [procedures[i] for i in nulls]  # one entry per procedure
    elif procedures and len(sample) == input_shape[0]:
        blocks = [block(procedures, input_shape, j) for j in range(len(procedures))]
        missing = [
            p
            for p, b in zip(procedures, blocks, strict=True)
            if all(sample[r] is None for r in range(b.start, b.stop))
        ]
    else:
        missing = []
    if missing:
        verb = "is" if len(missing) == 1 else "are"
        return (
            f"enrolment takes whole samples: {named_list(missing, 'procedure')} {verb} missing "
            "(null); send the sample once every procedure is done (POST /v1/recognize answers "
            "from some)"
        )
    return f"enrolment takes whole samples: row {nulls[0]} is null; send every value"


def _per_procedure(input_shape: tuple[int, ...], procedures: tuple[str, ...]) -> tuple[int, ...]:
    """The shape of a sample given as one entry per procedure."""
    rows = input_shape[0] // len(procedures)
    return (len(procedures), *((rows,) if rows > 1 else ()), *input_shape[1:])


def _nulls_as_nan(data: list, field: str) -> list[Any]:
    """``data`` with each null row a row of NaN shaped like the sample's other rows."""
    filled = [row for row in data if row is not None]
    if not filled:
        raise Problem(
            422, f"{field}: every procedure is missing (null); a sample needs at least one", field
        )
    try:
        with np.errstate(over="ignore"):  # only the shape is taken here; values are checked later
            nan = np.full(np.shape(np.asarray(filled[0], dtype=np.float32)), np.nan, np.float32)
    except ValueError:
        raise Problem(422, f"{field}: its rows have different lengths", field) from None
    return [nan if row is None else row for row in data]
