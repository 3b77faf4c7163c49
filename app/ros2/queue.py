"""The bridge's bounded queue of inputs waiting for their answers, in arrival order.

At most ``capacity`` inputs wait. An input that arrives while the queue is full is not
kept: its place in the order is, as a refusal that the worker answers with a 503 problem
when its turn comes, so every input still gets exactly one answer and answers keep their
order. Consecutive refusals share one entry (a count), so a service that stalls cannot
grow the queue past ``2 × capacity + 1`` entries.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any


@dataclass
class Work:
    """An input to answer: ``kind`` ``samples`` (an array), ``trial`` (a trial's JSON form),
    ``problem`` (its answer already known) or ``refused`` (``count`` inputs that found the
    queue full); ``received``: ``time.perf_counter()`` when it came."""

    kind: str
    payload: Any
    received: float
    count: int = 1


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
                self._items[-1].count += 1
                accepted = False
            else:
                self._items.append(Work("refused", None, work.received))
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

    def __len__(self) -> int:
        with self._ready:
            return self._waiting
