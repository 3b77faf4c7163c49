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
REST_SLACK = 1000  # frames a mark opening a trial may come late and keep its whole rest


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
        self.max_frames, self.rest_frames = max_frames, rest_frames
        # rest kept beyond rest_frames: a late mark opening a trial still gets its full rest
        self._rest: deque[np.ndarray] = deque(maxlen=rest_frames + REST_SLACK)
        self._frames: list[np.ndarray] | None = None  # None: no trial open
        self._phases: dict[str, tuple[int, int | None]] = {}
        self._current: str | None = None
        self._fault: str | None = None
        self._missing = 0  # frames of the open trial lost on the way (``lost``)
        self.completed_missing = 0  # of the trial the last completed procedure answers

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

    def lost(self, n: int) -> None:
        """``n`` frames were lost on the way just before the next one (``SequenceGaps``):
        counted against the open trial; lost rest frames are not counted."""
        if self._frames is not None:
            self._missing += n

    def fault(self, why: str) -> None:
        """A frame of the open trial could not be read: the trial's answers are problems."""
        if self._frames is not None and self._fault is None:
            self._fault = why

    def procedure(
        self, name: str, procedures: Sequence[str], late: int = 0
    ) -> dict[str, Any] | None:
        """Follow a procedure message; ``late``: how many of the frames received last were
        published after it (``ProcedureClock`` counts them), so that it falls before them."""
        name = name.strip()
        if name == END:
            if self._frames is None:
                raise TrialProblem("'end' with no trial open; name a procedure to start one")
            after = self._frames[len(self._frames) - late :] if late else []
            try:
                return self._complete(procedures, late) if self._current else None
            finally:
                self._reset()
                self._rest.extend(after)  # frames after the end are the next trial's rest
        if name == REST:
            if self._frames is None:
                raise TrialProblem(f"{REST!r} with no trial open; name a procedure to start one")
            return self._complete(procedures, late) if self._current else None
        if name not in procedures:
            raise TrialProblem(
                f"unknown procedure {name!r}; the model's procedures are "
                f"{', '.join(procedures) or '(none: it answers samples)'}; or {REST!r}, {END!r}"
            )
        if self._frames is None:
            self._frames = list(self._rest)[-(self.rest_frames + late) :]
            self._rest.clear()
        if name in self._phases:
            raise TrialProblem(
                f"procedure {name!r} was done already in this trial; publish {END!r} first"
            )
        try:
            return self._complete(procedures, late) if self._current else None
        finally:  # the new procedure starts even where the one before is a problem
            self._phases[name] = (max(0, len(self._frames) - late), None)
            self._current = name

    def _complete(self, procedures: Sequence[str], late: int = 0) -> dict[str, Any]:
        """Close the current procedure ``late`` frames before the last; the trial so far,
        its phases in the model's order."""
        assert self._frames is not None and self._current is not None
        name, (start, _) = self._current, self._phases[self._current]
        end = len(self._frames) - late
        self._current = None
        self.completed_missing = self._missing
        if self._fault is not None:
            raise TrialProblem(self._fault, "frames")
        if end <= start:
            del self._phases[name]
            raise TrialProblem(f"procedure {name!r} has no frames", "frames")
        self._phases[name] = (start, end)
        frames = np.stack(self._frames[:end])
        phases = [list(self._phases[p]) if p in self._phases else None for p in procedures]
        return {"fingers": fingers_of(frames), "phases": phases}

    def _reset(self) -> None:
        self._frames, self._phases, self._current, self._fault = None, {}, None, None
        self._missing = 0


class MarkOrder:
    """Puts procedure marks among the frames by their DDS source timestamps: frames and
    marks travel on two topics, and a backlog of frames (a busy bridge) would otherwise
    let a mark overtake frames published before it.

    A mark that comes before the frames published after it waits for the first of them;
    one that comes after such frames is placed ``late`` frames back. Marks wait at most
    ``wait`` seconds of no frames at all (a sensor that stopped streaming), seen at two
    flushes in a row with no frame between: a bridge stalled that long (a busy process)
    finds frames waiting, and the first flush after the stall runs before them. Stamps are
    the publishers' clocks: a mark and its frames should come from one host's clock."""

    def __init__(self, wait: float = 1.0, keep: int = 10_000) -> None:
        self.wait = wait
        self._stamps: deque[int] = deque(maxlen=keep)  # of the frames received last
        self._pending: deque[tuple[int, str]] = deque()
        self._last_frame = 0.0
        self._armed = False  # the last flush found the marks due: the next one follows them

    def frame(self, stamp: int, now: float) -> list[Any]:
        """The marks due before a frame stamped ``stamp``, in order; it is recorded."""
        due = []
        while self._pending and self._pending[0][0] <= stamp:
            due.append(self._pending.popleft()[1])
        self._stamps.append(stamp)
        self._last_frame, self._armed = now, False
        return due

    def mark(self, name: Any, stamp: int) -> list[tuple[Any, int]]:
        """The marks to follow now, each with how many frames it falls before. ``name``
        is passed through as it is (the bridge passes the mark with its message's
        ``InputRef``)."""
        if self._pending or not self._stamps or self._stamps[-1] < stamp:
            self._pending.append((stamp, name))
            return []
        late = 0
        for seen in reversed(self._stamps):
            if seen < stamp:
                break
            late += 1
        return [(name, late)]

    def flush(self, now: float) -> list[Any]:
        """Marks that waited ``wait`` seconds without a frame, at this flush and the one
        before with no frame between: follow them as they are."""
        if not self._pending or now - self._last_frame < self.wait:
            self._armed = False
            return []
        if not self._armed:
            self._armed = True
            return []
        self._armed = False
        return self.drain()

    def drain(self) -> list[Any]:
        """Every mark still waiting, in order (a recording's end: no frame will come)."""
        due = [name for _, name in self._pending]
        self._pending.clear()
        return due
