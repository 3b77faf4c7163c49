"""Hyper-parameters in scikit-learn's manner.

A recognizer's constructor only stores its arguments, each under its own name;
``get_params`` and ``set_params`` find the names in the constructor's signature,
and ``fit`` checks the values against the constraints the class declares once, in
``_parameter_constraints`` (parameter name -> ``Constraint``), before any work. A
check that involves several parameters goes into the class's ``_validate_params``.

A failed check raises ``FrameworkError`` (a ``ValueError``) naming the parameter,
what it must be and the value it got: ``dap_clip must lie in (0, 0.5), got 0.7``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.framework.errors import FrameworkError


def check(condition: bool, message: str) -> None:
    """Raise ``FrameworkError(message)`` unless ``condition`` holds."""
    if not condition:
        raise FrameworkError(message)


@dataclass(frozen=True)
class Constraint:
    """What a parameter's value must satisfy: ``test(value)`` is true, and ``must``
    completes the sentence "<name> must ..." for the error. A test that raises
    ``TypeError`` or ``ValueError`` (a string where a number belongs) fails."""

    test: Callable[[Any], bool]
    must: str

    def holds(self, value: Any) -> bool:
        try:
            return bool(self.test(value))
        except (TypeError, ValueError):
            return False

    def check(self, name: str, value: Any) -> None:
        check(self.holds(value), f"{name} must {self.must}, got {value!r}")


def one_of(options: Iterable[Any], must: str | None = None) -> Constraint:
    """One of ``options`` (compared with ``==``)."""
    options = tuple(options)
    return Constraint(lambda v: v in options, must or f"be one of {options}")


def either(*constraints: Constraint, must: str) -> Constraint:
    """Any one of ``constraints``."""
    return Constraint(lambda v: any(c.holds(v) for c in constraints), must)


def at_least(low: int) -> Constraint:
    """A value whose ``int()`` is at least ``low`` (2.0 and numpy integers pass)."""
    return Constraint(lambda v: int(v) >= low, f"be at least {low}")


def between(low: float, high: float) -> Constraint:
    """Strictly between ``low`` and ``high``, whatever its type."""
    return Constraint(lambda v: low < v < high, f"lie in ({low:g}, {high:g})")


def integer(low: int, must: str | None = None, *, allow_bool: bool = True) -> Constraint:
    """A Python or numpy integer of at least ``low``; ``allow_bool=False`` refuses True
    and False, which Python counts as integers."""

    def test(v: Any) -> bool:
        return (
            isinstance(v, int | np.integer) and (allow_bool or not isinstance(v, bool)) and v >= low
        )

    return Constraint(
        test, must or ("be a positive integer" if low == 1 else f"be an integer of at least {low}")
    )


def number(
    low: float,
    high: float | None = None,
    must: str | None = None,
    *,
    include_low: bool = False,
    allow_bool: bool = True,
    finite: bool = False,
) -> Constraint:
    """A Python number (int or float, numpy's float64 included) above ``low`` (or equal to
    it with ``include_low``) and below ``high``; ``finite`` refuses NaN and infinities."""

    def test(v: Any) -> bool:
        if not isinstance(v, int | float) or (not allow_bool and isinstance(v, bool)):
            return False
        if finite and not math.isfinite(v):
            return False
        above = v >= low if include_low else v > low
        return above and (high is None or v < high)

    if must is None:
        if high is not None:
            must = f"lie in ({low:g}, {high:g})"
        elif low == 0:
            must = "be a non-negative number" if include_low else "be positive"
        else:
            must = f"be a number {'at least' if include_low else 'above'} {low:g}"
    return Constraint(test, must)


def positive_values() -> Constraint:
    """A non-empty sequence of positive numbers."""
    return Constraint(lambda v: len(v) > 0 and min(v) > 0, "be positive values")
