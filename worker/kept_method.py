"""Which method a full refit fits: with ``auto``, the one chosen before, kept.

``auto`` chooses between its candidates by a probe (``app/methods/choice.py``). Choosing
again at every full refit would let a new version switch method under its users (at
30,000 objects a 4.26 GB ``best`` bundle against a 133 MB ``prototypes`` one, and another
operating point) on a probe's noise. So the choice is made once and kept, recorded in the
version's ``metrics.chosen_by``; a full refit chooses again only when

- the known classes have grown to ``TACTILE_RECHOOSE_GROWTH`` times those the choice was
  made at (the candidates' ranking moves with the catalogue's size: docs/BENCHMARKS.md), or
- an operator asked for it (``POST /v1/models/choice``, ``tactile-zsl model choose``),
  which queues a ``choose_method`` job.

A kept choice's record says so (``kept``, ``kept_since``: the version it was made in). A
change of method is logged at WARNING and shows in ``GET /v1/models`` (``method`` and
``method_choice`` of each version).
"""

from __future__ import annotations

import logging
from typing import Any

from app.config import Settings
from app.framework.defaults import AUTO
from app.framework.recognizer import TactileRecognizer

log = logging.getLogger(__name__)


def refit_method(
    settings: Settings,
    base: TactileRecognizer | None,
    base_version: int | None,
    n_known: int,
    asked: bool,
) -> tuple[str, dict[str, Any] | None]:
    """(the method a full refit of ``n_known`` known classes fits, the choice record it
    keeps, or None where it chooses anew). ``asked``: an operator asked for a new choice."""
    if settings.method != AUTO:
        return settings.method, None
    chosen = (base.metrics if base is not None else {}).get("chosen_by")
    if asked or not chosen or "n_classes" not in chosen:
        return AUTO, None
    grown = n_known >= settings.rechoose_growth * max(1, int(chosen["n_classes"]))
    if grown:
        log.info(
            "auto chooses again: %d known classes, %s times the %d it chose %s at",
            n_known,
            settings.rechoose_growth,
            chosen["n_classes"],
            chosen["method"],
        )
        return AUTO, None
    # the version that made the choice: the base, unless it kept it from an earlier one
    kept = {**chosen, "kept": True, "kept_since": chosen.get("kept_since", base_version)}
    return chosen["method"], kept


def record_choice(
    model: TactileRecognizer, kept: dict[str, Any] | None, base: TactileRecognizer | None
) -> TactileRecognizer:
    """``model`` with ``kept`` as its choice record, and a change of method logged."""
    if kept is not None:
        model.metrics = {**model.metrics, "chosen_by": kept}
    if base is not None and base.method != model.method:
        log.warning(
            "the new model's method is %s, where the model before it was %s (%s)",
            model.method,
            base.method,
            (model.metrics.get("chosen_by") or {}).get("reason", "settings"),
        )
    return model
