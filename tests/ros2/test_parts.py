"""The bridge's parts without DDS: the bounded queue, trial assembly from frames and
procedure marks, marks placed among frames by their stamps, and message shapes."""

from __future__ import annotations

import numpy as np
import pytest
from std_msgs.msg import Float32MultiArray

from app.ros2.arrays import (
    FRAME_WIDTH,
    MessageShapeError,
    fingers_of,
    frame_of,
    multiarray,
    samples_of,
)
from app.ros2.queue import AnswerQueue, Work
from app.ros2.trials import MarkOrder, TrialAssembler, TrialProblem

PROCEDURES = ("tap", "hold", "squeeze")


def test_a_full_queue_keeps_each_refused_input_in_its_place_in_one_entry_per_run():
    q = AnswerQueue(2)
    accepted = [q.put(Work("samples", i, 0.0)) for i in range(5)]
    assert accepted == [True, True, False, False, False] and q.refused == 3
    first = q.get(0.1)
    assert first.payload == 0
    assert q.put(Work("samples", 5, 0.0))  # a place freed: accepted, after the refusals
    got = [q.get(0.1) for _ in range(3)]
    assert [(w.kind, w.payload, w.count) for w in got] == [
        ("samples", 1, 1),
        ("refused", None, 3),
        ("samples", 5, 1),
    ]
    assert q.get(0.01) is None and len(q) == 0
    with pytest.raises(ValueError, match="at least 1"):
        AnswerQueue(0)


def frames(n: int, fingers: int = 2, start: float = 0.0) -> list[np.ndarray]:
    return [np.full((fingers, FRAME_WIDTH), start + k, np.float32) for k in range(n)]


def test_a_trial_is_answered_after_each_procedure_with_its_rest_and_phases():
    a = TrialAssembler(rest_frames=3)
    for f in frames(5):  # rest: only the last 3 are kept
        a.frame(f)
    assert a.procedure("tap", PROCEDURES) is None
    for f in frames(4, start=10):
        a.frame(f)
    first = a.procedure("rest", PROCEDURES)
    assert first["phases"] == [[3, 7], None, None]
    assert first["fingers"][0]["pdc"].tolist() == [2, 3, 4, 10, 11, 12, 13]
    assert first["fingers"][1]["pac"].shape == (7, 22)
    for f in frames(2, start=20):
        a.frame(f)
    assert a.procedure("hold", PROCEDURES) is None  # after rest: nothing in progress
    for f in frames(3, start=30):
        a.frame(f)
    second = a.procedure("end", PROCEDURES)
    assert second["phases"] == [[3, 7], [9, 12], None]
    assert not a.open


def test_marks_it_cannot_follow_are_problems_and_the_trial_goes_on():
    a = TrialAssembler(rest_frames=2)
    with pytest.raises(TrialProblem, match="'end' with no trial open"):
        a.procedure("end", PROCEDURES)
    with pytest.raises(TrialProblem, match="unknown procedure 'poke'"):
        a.procedure("poke", PROCEDURES)
    a.procedure("tap", PROCEDURES)
    with pytest.raises(TrialProblem, match="'tap' has no frames") as no_frames:
        a.procedure("hold", PROCEDURES)
    assert no_frames.value.problem["errors"] == [
        {"field": "frames", "reason": "procedure 'tap' has no frames"}
    ]
    for f in frames(3):
        a.frame(f)
    assert a.procedure("squeeze", PROCEDURES)["phases"] == [None, [0, 3], None]
    with pytest.raises(TrialProblem, match="'hold' was done already"):
        a.procedure("hold", PROCEDURES)
    a.frame(np.zeros((1, FRAME_WIDTH), np.float32))  # one finger of two
    with pytest.raises(TrialProblem, match="1 finger") as bad:
        a.procedure("end", PROCEDURES)
    assert bad.value.problem["status"] == 422 and not a.open


def test_a_mark_is_placed_among_frames_by_its_stamp_whichever_comes_first():
    order = MarkOrder(wait=1.0)
    assert order.frame(10, now=0.0) == []
    assert order.mark("tap", 15) == []  # ahead of the frames published after it: waits
    assert order.frame(12, now=0.01) == []
    assert order.frame(16, now=0.02) == ["tap"]
    assert order.frame(20, now=0.03) == []
    assert order.frame(21, now=0.04) == []
    assert order.mark("rest", 19) == [("rest", 2)]  # two frames overtook it
    assert order.mark("end", 30) == []
    assert order.flush(now=0.5) == []  # frames may still come
    assert order.flush(now=1.5) == []  # a stalled bridge may find frames waiting: once more
    assert order.frame(25, now=1.6) == []  # it did: not yet, and the wait starts again
    assert order.flush(now=1.7) == []
    assert order.flush(now=2.7) == []
    assert order.flush(now=2.8) == ["end"]

    a = TrialAssembler(rest_frames=5)
    for f in frames(4):
        a.frame(f)
    a.procedure("tap", PROCEDURES, late=1)  # frame 3 came after the mark
    for f in frames(3, start=4):
        a.frame(f)
    done = a.procedure("end", PROCEDURES, late=2)  # frames 5 and 6 came after it
    assert done["phases"] == [[3, 5], None, None]
    assert done["fingers"][0]["pdc"].tolist() == [0, 1, 2, 3, 4]
    a.procedure("tap", PROCEDURES)  # the frames after the end are the next trial's rest
    for f in frames(1, start=9):
        a.frame(f)
    assert a.procedure("rest", PROCEDURES)["fingers"][0]["pdc"].tolist() == [5, 6, 9]


def test_messages_take_their_layout_or_the_models_shape():
    x = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(samples_of(multiarray(x), (3, 4)), x)
    flat = Float32MultiArray(data=np.arange(24, dtype=np.float32).tolist())
    assert samples_of(flat, (3, 4)).shape == (2, 3, 4)
    assert samples_of(Float32MultiArray(data=[1.0] * 5), (3, 4)).shape == (5,)
    torn = multiarray(x)
    torn.data = torn.data[:-1]
    with pytest.raises(MessageShapeError, match=r"shape \[3, 4\] \(12 values\).*holds 11"):
        samples_of(torn, (3, 4))
    frame = np.arange(2 * FRAME_WIDTH, dtype=np.float32).reshape(2, FRAME_WIDTH)
    assert np.array_equal(frame_of(multiarray(frame)), frame)
    with pytest.raises(MessageShapeError, match="one row of 44 values per finger"):
        frame_of(multiarray(np.zeros((2, 43))))
    (finger,) = fingers_of(frame[None, :1])
    assert finger["pdc"].tolist() == [0] and finger["electrodes"].shape == (1, 19)
    assert finger["pac"][0].tolist() == list(range(3, 25))


def test_the_command_refuses_bad_options_by_name(capsys, tmp_path):
    from app.cli import main

    assert main(["ros2", "--url", "http://127.0.0.1:9", "--timeout", "0"]) == 2
    assert "--timeout must be > 0" in capsys.readouterr().err
    assert main(["ros2", "--model", str(tmp_path / "m.bundle"), "--api-key", "k"]) == 2
    assert "--api-key goes with --url" in capsys.readouterr().err
    assert main(["ros2", "--model", str(tmp_path / "absent.bundle")]) == 2
    assert "no model bundle at" in capsys.readouterr().err
