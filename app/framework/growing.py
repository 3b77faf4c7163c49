"""Arrays that grow by appending rows, without copying the rows they had.

A promotion learns a few new samples into a model of thousands of objects: its forests
and novelty reference gain rows at their ends, and the model before it keeps answering
meanwhile. Concatenating copies every row each time (gigabytes at 10,000 objects, most of
a promotion's time). Here an array lives in a buffer with spare rows behind it
(``with_room``), and ``appended`` writes the new rows into that spare room when the array
ends where the buffer's written rows end, so both the old array and the new one are
read-only views of the same memory. Spare room that is never written costs address space
only: the kernel backs a large allocation's pages when they are first written.

The arrays handed out are read-only, and so is the buffer (``bundle.unchangeable`` holds
for them, so models derived from them share them instead of copying): rows once handed
out are never written again. ``appended`` makes the buffer writable for as long as it
writes rows past every view handed out; a check of ``unchangeable`` in that moment, in
another thread, finds the views changeable, which costs a copy or a cache miss, never a
wrong answer.
"""

from __future__ import annotations

import itertools
import threading
import weakref
from collections.abc import Iterator
from typing import Any

import numpy as np

#: spare rows given to a buffer, as a share of the rows it holds when made
SPARE = 0.25

# buffer (by id, dropped when the buffer is freed) -> rows written
_rooms: dict[int, int] = {}
_lock = threading.Lock()


def with_room(*parts: np.ndarray, spare: float = SPARE) -> np.ndarray:
    """``np.concatenate(parts)`` (arrays of the same row shape and type), read-only, with
    room for ``spare`` x its rows more behind it, for ``appended``."""
    return gathered(iter(parts), sum(len(p) for p in parts), spare)


def gathered(parts: Iterator[np.ndarray], max_rows: int, spare: float = SPARE) -> np.ndarray:
    """``with_room`` of parts made one at a time, each copied before the next is asked for
    (so that it can be freed: a store's blocks, decoded one by one, are not all held beside
    the array they make up); ``max_rows`` bounds their rows."""
    first = np.asarray(next(parts))
    buffer = np.empty((max_rows + int(spare * max_rows) + 1, *first.shape[1:]), first.dtype)
    at = 0
    for part in itertools.chain([first], parts):
        buffer[at : at + len(part)] = part
        at += len(part)
    buffer.flags.writeable = False
    with _lock:
        _rooms[id(buffer)] = at
    weakref.finalize(buffer, _rooms.pop, id(buffer), None)
    return buffer[:at]


def buffer_of(rows: np.ndarray) -> np.ndarray | None:
    """The buffer this module made whose first rows ``rows`` are (an array ``with_room``
    or ``appended`` returned, or a view of its first rows), else None. Its rows handed out
    are never written again."""
    buffer = rows.base
    if not isinstance(buffer, np.ndarray):
        return None
    with _lock:
        ours = id(buffer) in _rooms
    same = (
        rows.__array_interface__["data"][0] == buffer.__array_interface__["data"][0]
        and rows.strides == buffer.strides
        and rows.dtype == buffer.dtype
    )
    return buffer if ours and same else None


def appended(rows: np.ndarray, *parts: np.ndarray, spare: float = SPARE) -> np.ndarray:
    """``np.concatenate([rows, *parts])``, read-only: written into the room behind ``rows``
    when it is a ``with_room`` or ``appended`` array that nothing has been appended to yet
    and the room is large enough, else into a new buffer with room (a copy)."""
    rows = np.asarray(rows)
    parts = tuple(np.asarray(p, rows.dtype).reshape(-1, *rows.shape[1:]) for p in parts)
    n_new = sum(len(p) for p in parts)
    buffer = buffer_of(rows)
    with _lock:
        fits = (
            buffer is not None
            and _rooms.get(id(buffer)) == len(rows)
            and len(rows) + n_new <= len(buffer)
        )
        if fits:
            at = len(rows)
            buffer.flags.writeable = True  # it owns its memory; the views stay read-only
            try:
                for part in parts:
                    buffer[at : at + len(part)] = part
                    at += len(part)
            finally:
                buffer.flags.writeable = False
            _rooms[id(buffer)] = at  # a second append to ``rows`` copies
    if not fits:
        return with_room(rows, *parts, spare=spare)
    return buffer[:at]


class WhileAlive:
    """Values kept per array object while it lives (by its id, dropped when it is freed):
    what a process derived from an array that nothing writes, for the next caller given
    the very same array."""

    def __init__(self) -> None:
        self._values: dict[int, Any] = {}
        self._lock = threading.Lock()

    def get(self, array: np.ndarray | None) -> Any | None:
        if array is None:
            return None
        with self._lock:
            return self._values.get(id(array))

    def put(self, array: np.ndarray | None, value: Any) -> None:
        if array is None:
            return
        with self._lock:
            if id(array) not in self._values:
                weakref.finalize(array, self._forget, id(array))
            self._values[id(array)] = value

    def _forget(self, key: int) -> None:
        with self._lock:
            self._values.pop(key, None)


class ByBuffer(WhileAlive):
    """What a process derived from an array's rows, kept by the buffer the array begins
    (``buffer_of``) while that buffer lives. Rows handed out are never written again, so
    what was derived from a buffer's first rows holds for every array that begins with
    them: a promoted version that another process built is loaded as the version before
    with rows appended (``bundles.PartCache.joined``), and only those rows need deriving.
    An array in no such buffer has nothing kept."""

    def get(self, rows: np.ndarray) -> Any | None:
        return super().get(buffer_of(rows))

    def put(self, rows: np.ndarray, value: Any) -> None:
        super().put(buffer_of(rows), value)
