"""Coalesces concurrent small recognize requests into one forward pass.

A single-sample pass costs a large part of a pass over dozens of samples (per-call
overhead dominates these small models), so under load, requests that arrive while a
pass runs are answered together by the next one. An idle service adds no wait: a
lone request starts its pass at once.

What each request gets back is made once per pass too: ``finish`` turns the pass's
``RecognitionBatch`` into something each request takes its rows of (by default the batch
itself; the service counts the pass and builds its JSON records there, so a robot's touch
does not pay for them alone).

Passes run on the event loop itself. Under the GIL a worker thread adds no
parallelism for passes this small, only hand-off and GIL-switching cost (measured:
about 15% fewer single-sample requests/s); a pass is capped at ``max_samples`` so
the loop is never held for more than a few milliseconds.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.framework.recognizer import RecognitionBatch
from app.service.holder import LoadedModel


@dataclass
class _Request:
    model: LoadedModel
    samples: np.ndarray  # validated (n, *input_shape)
    top_k: int
    known_kept: float | None  # the operating point the answer is routed by (None: the model's)
    finish_with: Hashable  # passed to ``finish`` (the service: the outlier policy)
    answer: asyncio.Future


#: ``finish(model, the pass's batch, finish_with)``: what each request takes its rows of
Finish = Callable[[LoadedModel, RecognitionBatch, Any], Sequence]


def _as_batch(model: LoadedModel, batch: RecognitionBatch, finish_with: Any) -> RecognitionBatch:
    return batch


class RecognitionBatcher:
    """``max_samples``: the most samples a pass takes; ``finish``: what a pass's answers
    become before each request takes its rows (the module docstring)."""

    def __init__(self, max_samples: int = 64, finish: Finish = _as_batch) -> None:
        self.max_samples = max_samples
        self.finish = finish
        self._queue: deque[_Request] = deque()
        self._draining = False  # only touched on the event loop: no lock needed

    async def recognize(
        self,
        model: LoadedModel,
        samples: np.ndarray,
        top_k: int,
        known_kept: float | None = None,
        finish_with: Hashable = None,
    ) -> Sequence:
        """The rows of ``samples`` in what ``finish`` made of their pass (by default a
        ``RecognitionBatch``); ``finish_with`` is passed to ``finish``."""
        loop = asyncio.get_running_loop()
        request = _Request(model, samples, top_k, known_kept, finish_with, loop.create_future())
        self._queue.append(request)
        if not self._draining:
            self._draining = True
            loop.create_task(self._drain())
        return await request.answer

    async def _drain(self) -> None:
        try:
            await asyncio.sleep(0)  # requests parsed in this loop iteration join the first pass
            while self._queue:
                batch = self._take()
                # one pass per model snapshot, top_k, operating point and finish_with: a
                # swap mid-queue changes no answer
                groups: dict[tuple, list[_Request]] = {}
                for r in batch:
                    key = (id(r.model), r.top_k, r.known_kept, r.finish_with)
                    groups.setdefault(key, []).append(r)
                for group in groups.values():
                    self._pass(group)
                await asyncio.sleep(0)  # let new requests in between passes
        finally:
            self._draining = False

    def _take(self) -> list[_Request]:
        taken, n = [], 0
        while self._queue and (not taken or n + len(self._queue[0].samples) <= self.max_samples):
            r = self._queue.popleft()
            taken.append(r)
            n += len(r.samples)
        return taken

    def _pass(self, group: list[_Request]) -> None:
        first = group[0]
        x = np.concatenate([r.samples for r in group]) if len(group) > 1 else first.samples
        try:
            batch = first.model.recognizer.recognize_batch(
                x, first.top_k, known_kept=first.known_kept
            )
            results = self.finish(first.model, batch, first.finish_with)
        except Exception as exc:
            for r in group:
                if not r.answer.done():  # a caller that went away is not answered
                    r.answer.set_exception(exc)
            return
        if len(group) == 1:  # a lone request takes the whole pass: no copy of its rows
            if not first.answer.done():
                first.answer.set_result(results)
            return
        start = 0
        for r in group:
            end = start + len(r.samples)
            if not r.answer.done():
                r.answer.set_result(results[start:end])
            start = end
