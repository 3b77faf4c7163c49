"""Trials cut from a stream of raw BioTac frames by contact, where no procedure marks were
recorded: ``ContactMarks`` turns the pressure signal into the marks a robot would have
published. The ROS 2 bridge (``contact_detection``) and ``tactile-zsl dataset bag`` (a bag
of frames alone) both feed their frames through it, so a recording cut live and from its
bag gives the same trials.

The rule is ``PhaseRule``'s (app/data/biotac_phases.py) made causal, on one finger's
``pdc`` (column 0 of a frame, ``app.ros2.arrays``):

1. While no trial is open, the resting level is the median of the last ``rest_frames``
   frames; a trial's level is frozen at its first contact (``PhaseRule`` takes the first
   ``rest_frames`` frames of the trial, which start before its first contact).
2. A frame is in contact while pdc exceeds that level by ``contact_counts``. A contact
   starts at its first such frame once ``min_frames`` frames have been in contact (a
   twitch never starts one) and ends at its last such frame + 1 once ``min_gap`` frames
   have not been: contacts split by shorter dips are one.
3. The k-th contact of a trial is the model's k-th procedure (its name at the start,
   ``rest`` at the end); ``end`` follows the last procedure's ``rest``.

``PhaseRule.peak_fraction`` (a share of the finger's largest rise over the whole trial)
cannot be known while the trial streams, so it is not applied; the pilot's contacts rise
100-500 counts and its rest noise stays under 1 count, so ``contact_counts`` alone
separates them (tests/ros2/test_contacts.py).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from app.data.biotac_phases import PhaseRule

END, REST = "end", "rest"


class ContactMarks:
    """``frame`` takes each raw frame ((fingers, 44)) in order and returns the marks due
    before it, each with ``late``: how many frames already taken come after its place (the
    ``TrialAssembler.procedure`` argument)."""

    def __init__(
        self, procedures: Sequence[str], rule: PhaseRule | None = None, finger: int = 0
    ) -> None:
        if not procedures:
            raise ValueError("contact detection needs the model's procedures; it has none")
        self.procedures = tuple(procedures)
        self.rule = rule or PhaseRule(n_phases=len(self.procedures))
        self.finger = finger
        self._recent: deque[float] = deque(maxlen=self.rule.rest_frames)
        self._seen = 0  # frames taken so far
        self._level: float | None = None  # the open trial's resting level
        self.done = 0  # contacts of the open trial
        self._start: int | None = None  # first frame of the contact being followed
        self._start_level: float | None = None
        self._inside = 0  # its frames in contact so far
        self._last = 0  # its last frame in contact
        self._confirmed = False

    @property
    def open(self) -> bool:
        return self._level is not None

    def frame(self, frame: np.ndarray) -> list[tuple[str, int]]:
        i, pdc = self._seen, float(np.asarray(frame)[self.finger, 0])
        self._seen += 1
        marks: list[tuple[str, int]] = []
        if self._start is None:
            level = self._level
            if level is None and len(self._recent) == self._recent.maxlen:
                level = float(np.median(np.fromiter(self._recent, float)))
            if level is not None and pdc - level > self.rule.contact_counts:
                self._start, self._start_level, self._inside, self._last = i, level, 0, i
        if self._start is not None:
            assert self._start_level is not None
            if pdc - self._start_level > self.rule.contact_counts:
                self._inside += 1
                self._last = i
                if not self._confirmed and self._inside >= self.rule.min_frames:
                    self._confirmed = True
                    self._level = self._start_level
                    marks.append((self.procedures[self.done], i - self._start))
            elif i - self._last >= self.rule.min_gap:
                marks += self._close(i)
        self._recent.append(pdc)
        return marks

    def drain(self) -> list[tuple[str, int]]:
        """The marks of a contact still open when the frames stop (a recording's end)."""
        return self._close(self._seen) if self._start is not None else []

    def _close(self, i: int) -> list[tuple[str, int]]:
        marks: list[tuple[str, int]] = []
        if self._confirmed:
            late = i - (self._last + 1)
            marks.append((REST, late))
            self.done += 1
            if self.done == len(self.procedures):
                marks.append((END, late))
                self._level, self.done = None, 0
                # the next trial's rest starts after this contact
                after = list(self._recent)[len(self._recent) - late :] if late else []
                self._recent.clear()
                self._recent.extend(after)
        self._start, self._start_level, self._confirmed = None, None, False
        return marks
