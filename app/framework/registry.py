"""Recognition methods by name, so bundles and ``evaluate --methods`` can find them."""

from __future__ import annotations

import importlib

# re-exported: DEFAULT_METHOD lives where app.config can read it without the methods
from app.framework.defaults import DEFAULT_METHOD as DEFAULT_METHOD
from app.framework.recognizer import TactileRecognizer

# name -> "module:Class"; imported lazily so that listing methods stays cheap.
METHODS: dict[str, str] = {
    "paper": "app.framework.paper:PaperRecognizer",
    # the paper's pipeline with its GMM fitted on CONV_XF features instead of raw inputs
    "paper-fgmm": "app.framework.paper:PaperFeatureGMMRecognizer",
    # baselines measured beside the paper (evaluation-only: no model bundles)
    "extratrees": "app.baselines.extra_trees:ExtraTreesRecognizer",
    "dap": "app.baselines.dap:DAPRecognizer",
    "eszsl": "app.baselines.eszsl:ESZSLRecognizer",
    # the method that measured best on PHAC-2 (docs/RESULTS.md; storable in bundles)
    "best": "app.methods.best:BestRecognizer",
    # class prototypes in a discriminant space with contact modes (app/methods/prototypes.py)
    "prototypes": "app.methods.prototypes:PrototypeRecognizer",
    # whichever of best and prototypes measures better on a probe of the training data
    # (app/methods/choice.py); its fit returns the winner's recognizer
    "auto": "app.methods.choice:MethodChoice",
}


class UnknownMethodError(ValueError):
    """A method name that is not registered."""


def method_class(name: str) -> type[TactileRecognizer]:
    try:
        target = METHODS[name]
    except KeyError:
        raise UnknownMethodError(
            f"unknown method '{name}'; choose from {', '.join(sorted(METHODS))}"
        ) from None
    module, _, cls = target.partition(":")
    return getattr(importlib.import_module(module), cls)


def make_method(name: str, **params) -> TactileRecognizer:
    return method_class(name)(**params)
