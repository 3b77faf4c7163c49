"""Arrays that grow by appending rows in the room behind them (``app.framework.growing``)."""

import gc

import numpy as np
import pytest

from app.framework import growing
from app.framework.bundle import unchangeable
from app.framework.growing import appended, with_room


def test_appending_writes_behind_the_rows_and_the_earlier_arrays_stay_as_they_were():
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((40, 3))
    a = with_room(rows[:10], rows[10:20], spare=1.0)  # room for 20 more rows
    np.testing.assert_array_equal(a, rows[:20])
    b = appended(a, rows[20:25], rows[25:30])
    c = appended(b, rows[30:35])
    np.testing.assert_array_equal(c, rows[:35])
    assert np.shares_memory(a, c)  # no row copied
    np.testing.assert_array_equal(a, rows[:20])
    np.testing.assert_array_equal(b, rows[:30])
    # read-only, and so is what they view: models derived from them may share them
    for array in (a, b, c):
        assert not array.flags.writeable and unchangeable(array)
        with pytest.raises(ValueError, match="read-only"):
            array[0, 0] = 1.0


def test_a_second_append_to_the_same_rows_copies_and_changes_nothing_else():
    a = with_room(np.arange(100))
    b = appended(a, [7, 8])
    other = appended(a, [9])  # b took the room behind a: a copy
    assert not np.shares_memory(other, a)
    np.testing.assert_array_equal(other, [*range(100), 9])
    np.testing.assert_array_equal(b, [*range(100), 7, 8])
    # nor can a shorter view of a buffer write over the rows of a longer one
    again = appended(b[:50], [1])
    assert not np.shares_memory(again, b)
    np.testing.assert_array_equal(b, [*range(100), 7, 8])


def test_arrays_without_room_and_appends_past_the_room_are_copied_into_new_room():
    plain = np.arange(6, dtype=np.int32)
    grown = appended(plain, np.array([6, 7], np.int64))
    assert grown.dtype == np.int32 and not np.shares_memory(grown, plain)
    np.testing.assert_array_equal(grown, np.arange(8))
    small = with_room(np.zeros((4, 2)), spare=0.25)  # room for 2 more rows
    assert np.shares_memory(appended(small, np.ones((2, 2))), small)
    big = appended(appended(small, np.ones((2, 2)))[:4], np.ones((3, 2)))
    assert not np.shares_memory(big, small)
    # the copy has room in turn
    assert np.shares_memory(appended(big, np.ones((1, 2))), big)


def test_a_buffer_is_forgotten_with_its_last_array():
    gc.collect()
    before = len(growing._rooms)
    a = with_room(np.zeros(1000))
    b = appended(a, np.ones(10))
    assert len(growing._rooms) == before + 1
    del a, b
    gc.collect()
    assert len(growing._rooms) == before


def test_what_was_derived_from_a_buffer_holds_for_arrays_that_begin_with_it():
    """``ByBuffer``: a value put for an array is found for any array its buffer's first rows
    make (one appended to it, a view of its first rows), not for a copy or an array that is
    in no buffer, and it goes with the buffer."""
    kept = growing.ByBuffer()
    a = with_room(np.zeros((100, 3)))
    kept.put(a, "derived")
    longer = appended(a, np.ones((4, 3)))
    assert kept.get(longer) == kept.get(a[:10]) == "derived"
    assert kept.get(a.copy()) is None and kept.get(np.zeros((100, 3))) is None
    kept.put(np.zeros(5), "nowhere")  # in no buffer: nothing kept
    assert len(kept._values) == 1
    copied = appended(a, np.ones((4, 3)))  # a second append to ``a``: a new buffer
    assert kept.get(copied) is None
    del a, longer
    gc.collect()
    assert len(kept._values) == 0
