"""How far a measured share of known touches kept may lie from the share an operating
point states, when it is measured on ``n`` held-out touches.

A threshold read off a calibration curve keeps the stated share ``p`` of the touches the
curve was measured on, to within the curve's resolution (its largest step in share kept:
one probe touch, or one threshold of the grid). On ``n`` touches it never saw, the share
kept is a binomial proportion around ``p``: three standard deviations,
``3 sqrt(p (1 - p) / n)``, cover it but about once in 370 draws. Touches of one object are
not independent, so this is a lower bound on the spread, not a guarantee; the tests that
use it hold out whole trials of many objects.
"""

from __future__ import annotations

import math

import numpy as np

SIGMAS = 3.0


def curve_resolution(known_kept: np.ndarray) -> float:
    """The largest step of a calibration curve's share kept: how far a threshold read off
    it may miss the share it was asked for on the curve's own touches."""
    return float(np.diff(np.asarray(known_kept, np.float64)).max())


def kept_tolerance(stated: float, n: int, resolution: float) -> float:
    """``SIGMAS`` binomial standard deviations of a share ``stated`` on ``n`` touches, plus
    the calibration curve's ``resolution``."""
    if n < 1 or not 0 < stated < 1:
        raise ValueError(f"need n >= 1 touches and a stated share in (0, 1), got {n}, {stated}")
    return SIGMAS * math.sqrt(stated * (1 - stated) / n) + resolution


def assert_keeps(kept: float, stated: float, n: int, resolution: float) -> None:
    """``kept`` (measured on ``n`` held-out known touches) is the ``stated`` share, within
    its binomial tolerance and the curve's resolution."""
    tolerance = kept_tolerance(stated, n, resolution)
    assert abs(kept - stated) <= tolerance, (
        f"kept {kept:.3f} of {n} held-out known touches for a stated {stated}: more than "
        f"{tolerance:.3f} away ({SIGMAS:g} binomial sigmas + resolution {resolution:.3f})"
    )
