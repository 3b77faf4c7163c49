"""Hyper-parameters in scikit-learn's manner.

A recognizer's constructor only stores its arguments, each under its own name;
``get_params`` and ``set_params`` find the names in the constructor's signature,
and ``fit`` checks the values against the constraints the class declares once, in
``_parameter_constraints`` (parameter name -> ``Constraint``), before any work. A
check that involves several parameters goes into the class's ``_validate_params``.

``Hyperparameters`` gives a class (``TactileRecognizer``) ``get_params``, ``set_params``
and the check of its constraints.

A failed check raises ``FrameworkError`` (a ``ValueError``) naming the parameter,
what it must be and the value it got: ``dap_clip must lie in (0, 0.5), got 0.7``.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, Self

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


class Hyperparameters:
    """``get_params``, ``set_params`` and ``_validate_params`` of a class whose constructor
    takes every hyper-parameter as a named argument and only stores it under the same name
    (scikit-learn's convention).

    Not scikit-learn's ``BaseEstimator``, whose versions of these differ (checked with
    scikit-learn 1.9): its ``_get_param_names`` sorts the names (``get_params`` keeps the
    signature's order, which model bundles store and ``tests/framework/test_params.py``
    pins) and skips ``**kwargs`` silently (refused here); its ``set_params`` raises a plain
    ``ValueError`` worded otherwise (here ``FrameworkError``, the framework's error, naming
    the valid parameters); and it adds a ``repr`` of the parameters and metadata-routing methods
    (``set_fit_request``, as ``fit`` takes a ``dataset``). Keeping the behaviour would
    override all but ``get_params``, whose ``deep`` would then differ only for a parameter
    holding an estimator, which no method has."""

    #: parameter name -> what its value must satisfy; checked by ``fit``. A subclass
    #: extends its parent's: ``{**Parent._parameter_constraints, ...}``.
    _parameter_constraints: ClassVar[dict[str, Constraint]] = {}

    @classmethod
    def _get_param_names(cls) -> list[str]:
        """The constructor's parameter names, in its signature's order (scikit-learn's
        ``BaseEstimator._get_param_names``, which sorts them)."""
        init = cls.__init__
        if init is object.__init__:
            return []
        names = []
        for p in inspect.signature(init).parameters.values():
            if p.name == "self":
                continue
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(
                    f"{cls.__name__}.__init__ must name every hyper-parameter "
                    f"(no *args or **kwargs), as scikit-learn requires"
                )
            names.append(p.name)
        return names

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The hyper-parameters, by name, as the constructor takes them (``deep`` is
        scikit-learn's; a recognizer has no nested estimators)."""
        return {name: getattr(self, name) for name in self._get_param_names()}

    def set_params(self, **params: Any) -> Self:
        """Set hyper-parameters by name; they are checked by the next ``fit``."""
        valid = self._get_param_names()
        for name, value in params.items():
            if name not in valid:
                raise FrameworkError(
                    f"invalid parameter {name!r} for {type(self).__name__}; "
                    f"its parameters are: {', '.join(valid)}"
                )
            setattr(self, name, value)
        return self

    def _validate_params(self) -> None:
        """Check every hyper-parameter against ``_parameter_constraints``; a subclass adds
        the checks that involve several parameters. Raises FrameworkError."""
        for name, constraint in self._parameter_constraints.items():
            constraint.check(name, getattr(self, name))
