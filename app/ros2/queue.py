"""The bridge's bounded queue of inputs waiting for their answers, in arrival order, and
what names each input in its answer (``InputRef``) and counts the inputs lost on the way
(``SequenceGaps``).

At most ``capacity`` inputs wait. An input that arrives while the queue is full is not
kept: its place in the order is, as a refusal that the worker answers with a 503 problem
when its turn comes, so every input still gets exactly one answer and answers keep their
order. Consecutive refusals share one entry, which keeps only each refused input's
``InputRef`` (a few numbers), so a service that stalls cannot grow the queue past
``2 × capacity + 1`` entries.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any


@dataclass(frozen=True)
class InputRef:
    """The message an answer is for: its publisher's ``sequence`` number (DDS's
    publication sequence number; None where the middleware gives none), its source
    ``stamp`` in ns, and ``index``, the sample's place in a message that held several
    (None: the answer is about the whole message). ``header``: the robot's
    ``std_msgs/Header`` as JSON, echoed where the input carried one."""

    sequence: int | None
    stamp: int
    index: int | None = None
    header: dict[str, Any] | None = None
    frames_missing: int | None = None  # a trial's frames lost on the way (trial answers)

    @classmethod
    def of(cls, info: Any) -> InputRef:
        """From rclpy's ``MessageInfo`` (a dict), or None for an input without one."""
        if not info:
            return cls(None, 0)
        return cls(info.get("publication_sequence_number"), int(info.get("source_timestamp", 0)))

    def at(self, index: int) -> InputRef:
        return replace(self, index=index)

    def json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "sequence": self.sequence,
            "stamp": {"sec": self.stamp // 10**9, "nanosec": self.stamp % 10**9},
            "index": self.index,
        }
        if self.header is not None:
            out["header"] = self.header
        if self.frames_missing is not None:
            out["frames_missing"] = self.frames_missing
        return out


@dataclass
class Work:
    """An input to answer: ``kind`` ``samples`` (an array), ``trial`` (a trial's JSON form),
    ``enrol`` (POST /v1/classes's body), ``problem`` (its answer already known) or
    ``refused`` (inputs that found the queue full, one ``InputRef`` each, in order);
    ``received``: ``time.perf_counter()`` when it came."""

    kind: str
    payload: Any
    received: float
    inputs: list[InputRef] = field(default_factory=lambda: [InputRef(None, 0)])

    @property
    def count(self) -> int:
        return len(self.inputs)


class AnswerQueue:
    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"the queue's capacity must be at least 1, got {capacity}")
        self.capacity = capacity
        self._items: deque[Work] = deque()
        self._waiting = 0  # inputs held (refusals excluded)
        self._ready = threading.Condition()
        self.refused = 0  # inputs refused since the start

    def put(self, work: Work) -> bool:
        """Queue ``work``; False when the queue was full and it was refused instead."""
        with self._ready:
            if self._waiting < self.capacity:
                self._items.append(work)
                self._waiting += 1
                accepted = True
            elif self._items and self._items[-1].kind == "refused":
                self._items[-1].inputs.extend(work.inputs)
                accepted = False
            else:
                self._items.append(Work("refused", None, work.received, list(work.inputs)))
                accepted = False
            self.refused += not accepted
            self._ready.notify()
            return accepted

    def get(self, timeout: float) -> Work | None:
        """The oldest entry, waiting up to ``timeout`` seconds; None if none came."""
        deadline = time.monotonic() + timeout
        with self._ready:
            while not self._items:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._ready.wait(left)
            work = self._items.popleft()
            self._waiting -= work.kind != "refused"
            return work

    def unget(self, work: Work) -> None:
        """Put ``work``, just taken, back at the head (the bridge was deactivated)."""
        with self._ready:
            self._items.appendleft(work)
            self._waiting += work.kind != "refused"

    def __len__(self) -> int:
        with self._ready:
            return self._waiting


class SequenceGaps:
    """Inputs lost on the way, from gaps in each publisher's sequence numbers: a sensor
    link that drops messages (best effort) or a subscription's keep-last history that
    overflowed. A publisher's first message starts its count (what it sent before the
    bridge heard it is not counted), and a number that goes back (a restarted
    publisher) starts it again."""

    def __init__(self) -> None:
        self._last: dict[bytes, int] = {}
        self.missing = 0  # since the start, all publishers

    def seen(self, info: Any) -> int:
        """How many messages of this message's publisher were lost just before it."""
        if not info or info.get("publication_sequence_number") is None:
            return 0
        gid = info.get("publisher_gid") or {}
        key = bytes(gid.get("data", b"")) if isinstance(gid, dict) else b""
        seq = int(info["publication_sequence_number"])
        last = self._last.get(key)
        self._last[key] = seq
        if last is None or seq <= last:
            return 0
        lost = seq - last - 1
        self.missing += lost
        return lost
