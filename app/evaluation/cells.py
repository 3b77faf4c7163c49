"""The cells of the evaluation reports' markdown tables: a figure, a mean with its
interval, an interval alone; ``—`` where nothing was measured."""

from __future__ import annotations

from typing import Any

import numpy as np


def fmt(v: Any, std: Any = None) -> str:
    """``0.612``, or ``0.612 ± 0.020`` with a standard deviation."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    return f"{v:.3f}" if std is None else f"{v:.3f} ± {std:.3f}"


def fmt_ci(mean: Any, ci: Any, signed: bool = False) -> str:
    """``0.612 [0.590, 0.634]``; ``—`` when not measured; the mean alone without an interval."""
    if mean is None or (isinstance(mean, float) and not np.isfinite(mean)):
        return "—"
    form = "{:+.3f}" if signed else "{:.3f}"
    if not ci or any(v is None or not np.isfinite(v) for v in ci):
        return form.format(mean)
    return f"{form.format(mean)} [{form.format(ci[0])}, {form.format(ci[1])}]"


def fmt_interval(ci: Any) -> str:
    """``[0.590, 0.634]``; ``—`` without a finite interval."""
    if not ci or any(v is None or not np.isfinite(v) for v in ci):
        return "—"
    return f"[{ci[0]:.3f}, {ci[1]:.3f}]"
