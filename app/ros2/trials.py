"""Raw BioTac frames assembled into trials, their phases marked by ``~/procedure`` messages.

A trial opens with the first procedure named after ``end`` (or after the bridge started);
the ``rest_frames`` frames received just before it come along as its resting level (the
tactile image subtracts it, ``app.framework.tactile_image``). Each procedure runs from
its message to the next message: ``rest`` (the procedure is done, the finger rests), the
next procedure, or ``end``. That message completes it, and the trial so far, with the
procedures not done yet as null phases, is what the bridge answers then: one answer per
completed procedure, each naming the ``next_procedure`` to do (null once the answer is
confident). ``end`` closes the trial; frames until the next procedure are rest. A
procedure message the assembler cannot follow (a name the model does not know, a
procedure done twice in one trial, ``rest`` or ``end`` with no trial open) and a trial
with a bad frame get a problem in their answer's place.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from app.api.problems import problem_body
from app.ros2.arrays import fingers_of

END = "end"
REST = "rest"
RECOGNIZE = "/v1/recognize"


class TrialProblem(Exception):
    """A procedure message or a trial that cannot be answered; ``problem`` says why."""

    def __init__(self, detail: str, field: str = "procedure") -> None:
        super().__init__(detail)
        self.problem = problem_body(422, detail, RECOGNIZE, [{"field": field, "reason": detail}])


class TrialAssembler:
    """``frame`` takes each raw frame ((fingers, 44), ``app.ros2.arrays``), ``procedure``
    each procedure message and returns the trial to answer (its JSON form, arrays inside)
    when the message completes a procedure, else None; TrialProblem otherwise."""

    def __init__(self, rest_frames: int = 100, max_frames: int = 60_000) -> None:
        if rest_frames < 1 or max_frames < 2:
            raise ValueError("rest_frames must be ≥ 1 and max_frames ≥ 2")
        self.max_frames = max_frames
        self._rest: deque[np.ndarray] = deque(maxlen=rest_frames)
        self._frames: list[np.ndarray] | None = None  # None: no trial open
        self._phases: dict[str, tuple[int, int | None]] = {}
        self._current: str | None = None
        self._fault: str | None = None

    @property
    def open(self) -> bool:
        return self._frames is not None

    def frame(self, frame: np.ndarray) -> None:
        if self._frames is None:
            if self._rest and self._rest[-1].shape != frame.shape:
                self._rest.clear()  # another sensor set-up: its rest says nothing of this one
            self._rest.append(frame)
            return
        if self._fault is not None:
            return
        if self._frames and frame.shape != self._frames[0].shape:
            self.fault(
                f"frame {len(self._frames)} has {len(frame)} finger(s) where the trial's "
                f"first frame has {len(self._frames[0])}"
            )
        elif len(self._frames) >= self.max_frames:
            self.fault(f"the trial is longer than {self.max_frames} frames; publish 'end'")
        else:
            self._frames.append(frame)

    def fault(self, why: str) -> None:
        """A frame of the open trial could not be read: the trial's answers are problems."""
        if self._frames is not None and self._fault is None:
            self._fault = why

    def procedure(self, name: str, procedures: Sequence[str]) -> dict[str, Any] | None:
        name = name.strip()
        if name == END:
            if self._frames is None:
                raise TrialProblem("'end' with no trial open; name a procedure to start one")
            try:
                return self._complete(procedures) if self._current else None
            finally:
                self._reset()
        if name == REST:
            if self._frames is None:
                raise TrialProblem(f"{REST!r} with no trial open; name a procedure to start one")
            return self._complete(procedures) if self._current else None
        if name not in procedures:
            raise TrialProblem(
                f"unknown procedure {name!r}; the model's procedures are "
                f"{', '.join(procedures) or '(none: it answers samples)'}; or {REST!r}, {END!r}"
            )
        if self._frames is None:
            self._frames = list(self._rest)
            self._rest.clear()
        if name in self._phases:
            raise TrialProblem(
                f"procedure {name!r} was done already in this trial; publish {END!r} first"
            )
        try:
            return self._complete(procedures) if self._current else None
        finally:  # the new procedure starts even where the one before is a problem
            self._phases[name] = (len(self._frames), None)
            self._current = name

    def _complete(self, procedures: Sequence[str]) -> dict[str, Any]:
        """Close the current procedure; the trial so far, its phases in the model's order."""
        assert self._frames is not None and self._current is not None
        name, (start, _) = self._current, self._phases[self._current]
        end = len(self._frames)
        self._current = None
        if self._fault is not None:
            raise TrialProblem(self._fault, "frames")
        if end <= start:
            del self._phases[name]
            raise TrialProblem(f"procedure {name!r} has no frames", "frames")
        self._phases[name] = (start, end)
        frames = np.stack(self._frames)
        phases = [list(self._phases[p]) if p in self._phases else None for p in procedures]
        return {"fingers": fingers_of(frames), "phases": phases}

    def _reset(self) -> None:
        self._frames, self._phases, self._current, self._fault = None, {}, None, None
