"""Exploration phases of a raw BioTac finger: ``PhaseRule`` finds them in its ``pdc`` (DC
pressure) where a trial does not carry them (docs/DATASETS.md)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from app.data.biotac_errors import RawTrialError


@dataclass(frozen=True)
class PhaseRule:
    """How the exploration phases of a finger are found in its ``pdc`` (DC pressure).

    1. The resting level is the median of the first ``rest_frames`` frames (a trial starts
       before the first contact).
    2. A frame is in contact while pdc exceeds the resting level by ``contact_counts``.
    3. A contact counts when its peak exceeds the resting level by ``peak_fraction`` of the
       finger's largest rise (and by ``contact_counts``), so a short twitch does not.
    4. Contacts separated by fewer than ``min_gap`` frames are one contact; contacts of
       fewer than ``min_frames`` frames are dropped.
    5. There must be exactly ``n_phases`` contacts: they are the phases, ``[start, end)``
       frame ranges in time order. Otherwise RawTrialError (channel 'pdc') says how many
       there were, or that the finger never touched.

    The defaults fit the pilot's recordings (tap, hold, squeeze; ~100 frames/s, rest noise
    under 1 count, contacts 100-500 counts above rest) and find its three phases in every
    finger of its 74 trials (tests/data/test_biotac_pilot.py).
    """

    n_phases: int = 3
    rest_frames: int = 100
    contact_counts: float = 10.0
    peak_fraction: float = 0.1
    min_gap: int = 20
    min_frames: int = 3

    def __post_init__(self) -> None:
        for name in ("n_phases", "rest_frames", "min_frames"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(
                    f"PhaseRule.{name} must be an integer >= 1, got {getattr(self, name)!r}"
                )
        if not isinstance(self.min_gap, int) or self.min_gap < 0:
            raise ValueError(f"PhaseRule.min_gap must be an integer >= 0, got {self.min_gap!r}")
        if not (math.isfinite(self.contact_counts) and self.contact_counts > 0):
            raise ValueError(f"PhaseRule.contact_counts must be > 0, got {self.contact_counts!r}")
        if not 0.0 <= self.peak_fraction < 1.0:
            raise ValueError(
                f"PhaseRule.peak_fraction must lie in [0, 1), got {self.peak_fraction!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def resting_level(self, pdc: np.ndarray) -> float:
        return float(np.median(np.asarray(pdc)[: self.rest_frames]))

    def find(self, pdc: np.ndarray) -> tuple[tuple[int, int], ...]:
        """The ``n_phases`` ``[start, end)`` frame ranges of one finger's pdc."""
        pdc = np.asarray(pdc, dtype=np.float64)
        if len(pdc) <= self.rest_frames:
            raise RawTrialError(
                f"the finger is too short to find phases in: {len(pdc)} frames, the resting "
                f"level alone takes the first {self.rest_frames}",
                channel="pdc",
            )
        rise = pdc - self.resting_level(pdc)
        peak = float(rise.max())
        if peak <= self.contact_counts:
            raise RawTrialError(
                f"no contact to find a phase in: pdc never rises more than "
                f"{self.contact_counts:g} counts above its resting level (its largest rise "
                f"is {peak:g})",
                channel="pdc",
            )
        starts, ends = _runs(rise > self.contact_counts)
        high = max(self.contact_counts, self.peak_fraction * peak)
        keep = [
            k for k, (s, e) in enumerate(zip(starts, ends, strict=True)) if rise[s:e].max() > high
        ]
        starts, ends = starts[keep], ends[keep]
        if len(starts) > 1:  # merge contacts split by short dips
            join = (starts[1:] - ends[:-1]) < self.min_gap
            starts = starts[np.r_[True, ~join]]
            ends = ends[np.r_[~join, True]]
        long = (ends - starts) >= self.min_frames
        starts, ends = starts[long], ends[long]
        if len(starts) != self.n_phases:
            found = ", ".join(f"[{s}, {e})" for s, e in zip(starts, ends, strict=True))
            raise RawTrialError(
                f"found {len(starts)} contact(s) ({found}) where {self.n_phases} exploration "
                f"phases are expected",
                channel="pdc",
            )
        return tuple((int(s), int(e)) for s, e in zip(starts, ends, strict=True))


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and (exclusive) ends of the runs of True in a 1-D boolean mask."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
