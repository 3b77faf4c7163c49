"""``TACTILE_METHOD_PARAMS``: each method's hyper-parameters under its own name.

A service fits more than one method over its life: ``auto`` fits its candidates, and a
refit keeps the method chosen before (``worker/retrain.py``). So the setting names each
method, ``{"best": {"n_estimators": 200}, "auto": {"probe_classes": 50}}``, and is checked
when the settings are read: an unknown method, a parameter the method's constructor does
not take, or a value its constraints refuse stops the service at start with a message that
names the fix, never at the first refit.
"""

from __future__ import annotations

from typing import Any

from app.framework.defaults import AUTO


def check_params_by_method(value: Any) -> dict[str, dict[str, Any]]:
    """``value`` if every key names a registered method and every value is keyword
    arguments its constructor takes and its constraints accept; ValueError otherwise."""
    from app.framework.registry import METHODS, method_class

    if not isinstance(value, dict):
        raise ValueError(
            "TACTILE_METHOD_PARAMS must be a JSON object of methods' parameters by method "
            f'name, e.g. {{"best": {{"n_estimators": 200}}}}; got {type(value).__name__}'
        )
    flat = [k for k in value if k not in METHODS]
    if flat:
        hint = (
            f'write {{"best": {{"{flat[0]}": ...}}}} (or the method that takes it)'
            if not isinstance(value[flat[0]], dict)
            else f"registered methods: {', '.join(sorted(METHODS))}"
        )
        raise ValueError(
            f"TACTILE_METHOD_PARAMS names {flat}, which are not methods: parameters go "
            f"under their method's name; {hint}"
        )
    for name, params in value.items():
        if not isinstance(params, dict):
            raise ValueError(
                f"TACTILE_METHOD_PARAMS[{name!r}] must be a JSON object of {name}'s "
                f"parameters, got {type(params).__name__}"
            )
        cls = method_class(name)
        takes = set(cls._get_param_names())
        unknown = sorted(set(params) - takes)
        if unknown:
            raise ValueError(
                f"TACTILE_METHOD_PARAMS[{name!r}] has {unknown}, which {name} does not take; "
                f"its parameters: {', '.join(sorted(takes))}"
            )
        if name == AUTO and "params" in params:
            raise ValueError(
                "TACTILE_METHOD_PARAMS['auto'] must not hold 'params': give each candidate's "
                'parameters under its own name, e.g. {"best": {...}, "prototypes": {...}}'
            )
        try:
            cls(**params)._validate_params()
        except ValueError as error:
            raise ValueError(f"TACTILE_METHOD_PARAMS[{name!r}]: {error}") from None
    return value


def check_placed(method: str, params_by_method: dict[str, dict[str, Any]]) -> None:
    """ValueError where ``params_by_method`` names a method that ``method`` never fits: a
    method other than itself, or for ``auto`` other than itself and its candidates."""
    from app.methods.choice import CANDIDATES

    fitted = {method}
    if method == AUTO:
        fitted |= set(params_by_method.get(AUTO, {}).get("candidates", CANDIDATES))
    misplaced = sorted(set(params_by_method) - fitted)
    if misplaced:
        raise ValueError(
            f"TACTILE_METHOD_PARAMS names {misplaced}, which TACTILE_METHOD={method} never "
            f"fits: give parameters for {sorted(fitted)} only, or set TACTILE_METHOD"
        )


def params_for(method: str, params_by_method: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The keyword arguments that make ``method``: its own parameters, and for ``auto`` its
    candidates' under ``params`` (``MethodChoice``)."""
    own = dict(params_by_method.get(method, {}))
    if method == AUTO:
        from app.methods.choice import CANDIDATES

        candidates = own.get("candidates", CANDIDATES)
        theirs = {c: dict(params_by_method[c]) for c in candidates if c in params_by_method}
        if theirs:
            own["params"] = theirs
    return own
