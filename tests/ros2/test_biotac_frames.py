"""Raw BioTac frames over DDS: the real pilot recordings replayed frame by frame (ten times
their recorded rate, to keep the suite short; bench/ros2.py replays at the recorded rate)
into a real ``tactile-zsl ros2`` bridging a real ``serve`` trained on four of every five
trials. After each procedure the bridge answers the trial so far, as HTTP answers the same
frames; held-out trials are recognised."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from app.client import TactileClient
from app.data.biotac import read_biotac_h5, write_biotac_h5
from app.ros2.arrays import fingers_of, frames_of, multiarray
from app.testing.ros2 import replay_trial

from .conftest import PILOT, serve

pytestmark = pytest.mark.slow

OBJECTS = ("bouncy_foam", "cork", "glass_bottle", "hard_rough_foam")
PERIOD = 0.001  # seconds between frames: 10× the pilot's ~100 Hz


@pytest.fixture(scope="module")
def pilot(tmp_path_factory):
    """(the URL of a service trained on four objects' trials, one held-out trial each)."""
    if not (PILOT / "cork.h5").is_file():
        pytest.skip(f"BioTac pilot data not found at {PILOT.resolve()}")
    folder = tmp_path_factory.mktemp("biotac")
    held = {}
    for name in OBJECTS:
        trials = read_biotac_h5(PILOT / f"{name}.h5")
        names = sorted(trials)
        write_biotac_h5(folder / f"{name}.h5", {n: trials[n] for n in names[1:]})
        held[name] = trials[names[0]]
    env = {"TACTILE_DATASET": f"biotac:{folder}"}
    for url in serve(tmp_path_factory.mktemp("pilot-service"), env):  # its teardown follows
        yield url, held


def http_answer(url: str, trial: dict) -> dict:
    return httpx.post(f"{url}/v1/recognize", json={"trials": [trial]}, timeout=120).json()


def test_replayed_recordings_get_the_answers_http_gives_after_each_procedure(pilot, bridge_factory):
    url, held = pilot
    procedures = tuple(httpx.get(f"{url}/v1/models/active").json()["procedures"])
    bridge = bridge_factory("--url", url)
    published, right = 0, 0
    for name, trial in held.items():
        replay = replay_trial(bridge, trial, procedures, PERIOD)
        published += replay.frames
        got = bridge.next_answers(len(procedures), timeout=120)
        # each answer names the mark that completed its procedure; no frame was lost
        assert [a.body["input"]["frames_missing"] for a in got] == [0] * len(procedures)
        answers = [{k: v for k, v in a.body.items() if k != "input"} for a in got]
        assert answers == [http_answer(url, t) for t in replay.expected], name
        used = [a["results"][0]["procedures_used"] for a in answers]
        assert used == [list(procedures[: i + 1]) for i in range(len(procedures))]
        assert answers[0]["results"][0]["next_procedure"] in procedures[1:]
        right += answers[-1]["results"][0]["class_name"] == name
    assert right >= 3, f"{right} of {len(held)} held-out trials recognised"
    # the frames after the last answer's mark may still be on their way: wait for every
    # one (diagnostics whose count falls short after a minute say they were lost)
    diagnostics = heard_every_frame(bridge, published, len(held) * len(procedures))
    assert diagnostics["bad_frames"] == "0" and diagnostics["level"] == 0


def heard_every_frame(bridge, published: int, answered: int) -> dict:
    """The bridge's diagnostics once they count ``answered`` answers and ``published``
    frames, waiting on them rather than on time; AssertionError if frames were lost."""
    try:
        return bridge.wait_diagnostics(
            lambda d: d["answered"] == str(answered) and d["frames"] == str(published),
            timeout=60,
        )
    except AssertionError:
        raise AssertionError(
            f"frames were lost on the way: {published} published, diagnostics {bridge.diagnostics}"
        ) from None


def test_procedure_marks_it_cannot_follow_are_answered_with_a_problem(pilot, bridge_factory):
    url, held = pilot
    bridge = bridge_factory("--url", url)
    frames = frames_of(held["cork"])
    bridge.procedure("end")  # no trial open
    bridge.procedure("wiggle")  # no such procedure
    bridge.procedure("tap")
    bridge.procedure("tap")  # twice in one trial
    bridge.procedure("hold")  # tap has no frames
    for frame in frames[:50]:
        bridge.publish_frame(frame)
    bridge.publish_frame(frames[50, :1])  # one finger where the trial has two
    bridge.procedure("rest")  # completes hold: its trial has the bad frame
    bridge.procedure("end")
    answers = [a.body for a in bridge.next_answers(5)]
    assert [a["status"] for a in answers] == [422] * 5, answers
    details = [a["detail"] for a in answers]
    assert "'end' with no trial open" in details[0]
    assert "unknown procedure 'wiggle'" in details[1] and "tap, hold, squeeze" in details[1]
    assert "'tap' was done already" in details[2]
    assert "'tap' has no frames" in details[3]
    assert "1 finger(s) where the trial's first frame has 2" in details[4]
    assert answers[4]["errors"] == [{"field": "frames", "reason": details[4]}]


def test_the_model_file_answers_replayed_frames_as_the_service(
    pilot, bridge_factory, tmp_path: Path
):
    url, held = pilot
    model_file = tmp_path / "hand.bundle"
    with TactileClient(url, model_file=model_file) as client:
        assert client.sync_model()
    procedures = tuple(httpx.get(f"{url}/v1/models/active").json()["procedures"])
    bridge = bridge_factory("--model", str(model_file))
    replay = replay_trial(bridge, held["glass_bottle"], procedures, PERIOD)
    answers = [
        {k: v for k, v in a.body.items() if k != "input"}
        for a in bridge.next_answers(len(procedures), timeout=120)
    ]
    heard_every_frame(bridge, replay.frames, len(procedures))
    assert answers == [http_answer(url, t) for t in replay.expected]


def test_frames_lost_on_the_way_are_counted_and_named_in_the_trials_answer(pilot, bridge_factory):
    """A subscription history of one frame overflows under a burst: frames are lost in
    the bridge's own queue, and the gaps in their sequence numbers count them."""
    url, held = pilot
    bridge = bridge_factory("--url", url, params={"frame_depth": 1})
    frames = frames_of(held["cork"])
    for frame in frames[:150]:
        bridge.publish_frame(frame)
        time.sleep(0.002)
    time.sleep(1.5)  # a diagnostics period after the rest's last frame
    rest = dict(bridge.diagnostics)
    # frames lost before the first one heard are not counted: the count starts there
    heard_from = int(rest["frames"]) + int(rest["frames_missing"])
    bridge.procedure("tap")
    time.sleep(0.5)
    published = 150
    for _ in range(5):  # a burst as fast as the robot's side can publish
        for frame in frames[150:1150]:
            bridge.publish_frame(frame)
        published += 1000
        time.sleep(1.5)
        if int(bridge.diagnostics["frames_missing"]) > int(rest["frames_missing"]):
            break
    bridge.procedure("rest")
    (answer,) = bridge.next_answers(1, timeout=120)
    diagnostics = bridge.wait_diagnostics(lambda d: d["answered"] == "1")
    missing = int(diagnostics["frames_missing"])
    assert missing > 0, "no frame was lost: the test did not overflow the history"
    assert int(diagnostics["frames"]) + missing == published - (150 - heard_from)
    # the trial's answer counts the frames it lost (not those of its rest)
    assert answer.body["input"]["frames_missing"] == missing - int(rest["frames_missing"])


def test_a_recording_cut_live_and_from_its_bag_gives_the_same_trials(
    pilot, bridge_factory, ros, tmp_path
):
    """One replay, heard by the bridge and by a recorder as ``ros2 bag record`` hears it
    (each message at its receipt time): the bag's trial is the one the bridge answered."""
    from std_msgs.msg import Float32MultiArray, String

    from app.data.rosbag import bag_trials
    from app.ros2 import topics

    from .test_bags import ARRAY, TEXT, write_bag

    url, held = pilot
    procedures = tuple(httpx.get(f"{url}/v1/models/active").json()["procedures"])
    bridge = bridge_factory("--url", url)
    heard: list[tuple[str, str, int, object]] = []

    def recorder(topic: str, kind: str):
        return lambda msg, info: heard.append((topic, kind, info["received_timestamp"], msg))

    frames_topic, marks_topic = f"{bridge.prefix}/frames", f"{bridge.prefix}/procedure"
    subs = [
        ros.node.create_subscription(
            Float32MultiArray,
            frames_topic,
            recorder(frames_topic, ARRAY),
            topics.sensor_qos(10_000),
        ),
        ros.node.create_subscription(
            String, marks_topic, recorder(marks_topic, TEXT), topics.reliable_qos(100)
        ),
    ]
    deadline = time.monotonic() + 20
    while (
        bridge.frames.get_subscription_count() < 2 or bridge.procedures.get_subscription_count() < 2
    ):
        assert time.monotonic() < deadline, "the recorder never matched"
        time.sleep(0.05)
    replay = replay_trial(bridge, held["cork"], procedures, period=0.01)
    answers = bridge.next_answers(len(procedures), timeout=120)
    time.sleep(0.5)
    ros.destroy(*subs)
    assert len([m for m in heard if m[1] == ARRAY]) == replay.frames

    live = [{k: v for k, v in a.body.items() if k != "input"} for a in answers]
    assert live == [http_answer(url, t) for t in replay.expected]
    bag = write_bag(tmp_path / "cork_live", sorted(heard, key=lambda m: m[2]), "mcap")
    (trial,) = bag_trials(bag, procedures)
    expected = replay.expected[-1]
    assert [list(p) for p in trial.phases] == expected["phases"]
    for got, want in zip(trial.fingers, expected["fingers"], strict=True):
        for channel, values in want.items():
            assert np.array_equal(getattr(got, channel), np.asarray(values, np.float32)), channel


def test_without_marks_the_bridge_cuts_trials_by_contact_as_the_bag_import_does(
    pilot, bridge_factory, tmp_path
):
    """contact_detection:=true, two held-out recordings replayed at their recorded rate
    with no marks: the bridge answers after each contact the trials the bag import cuts
    from the same frames (exactly), and those trials are the marked ones (three
    procedures, boundaries within ``CONTACT_TOLERANCE`` frames of the phases the marked
    replays use, ``PhaseRule``'s)."""
    from app.data.rosbag import bag_trials

    from .test_bags import ARRAY, CONTACT_TOLERANCE, write_bag

    url, held = pilot
    procedures = tuple(httpx.get(f"{url}/v1/models/active").json()["procedures"])
    bridge = bridge_factory("--url", url, params={"contact_detection": "true"})
    bridge.procedure("tap")  # a mark is not followed, and its answer says why
    (refused,) = bridge.next_answers(1)
    assert refused.body["status"] == 422
    assert "cuts trials by contact" in refused.body["detail"], refused.body
    published = 0
    for name in ("cork", "glass_bottle"):
        trial = held[name]
        frames, phases = frames_of(trial), trial.phase_bounds()[0]
        first = max(0, phases[0][0] - 150)
        played = frames[first : phases[-1][1] + 30]
        replay_frames(bridge, played, period=0.01)
        published += len(played)
        live = [
            {k: v for k, v in a.body.items() if k != "input"}
            for a in bridge.next_answers(len(procedures), timeout=120)
        ]
        # the bag import's contact cut of the same frames
        stamps = 10**18 + 10**7 * np.arange(len(played))
        messages = [
            (f"{bridge.prefix}/frames", ARRAY, int(t), multiarray(f))
            for t, f in zip(stamps, played, strict=True)
        ]
        (cut,) = bag_trials(write_bag(tmp_path / name, messages, "mcap"), procedures)
        cut_frames, cut_phases = frames_of(cut), [list(p) for p in cut.phases]
        expected = [
            {
                "fingers": [
                    {k: v.tolist() for k, v in f.items()} for f in fingers_of(cut_frames[:end])
                ],
                "phases": [p if j <= i else None for j, p in enumerate(cut_phases)],
            }
            for i, (_, end) in enumerate(cut_phases)
        ]
        assert live == [http_answer(url, t) for t in expected], name
        # the cut trial is the marked one: its frames from near where the marked one's start
        marked = phases[0][0] - first - 100
        near = range(marked - CONTACT_TOLERANCE, marked + CONTACT_TOLERANCE + 1)
        (origin,) = [o for o in near if np.array_equal(cut_frames, played[o : o + len(cut_frames)])]
        for (s, e), (ms, me) in zip(cut_phases, phases, strict=True):
            assert abs(first + origin + s - ms) <= CONTACT_TOLERANCE, (name, cut_phases, phases)
            assert abs(first + origin + e - me) <= CONTACT_TOLERANCE, (name, cut_phases, phases)
    heard_every_frame(bridge, published, 1 + 2 * len(procedures))


def replay_frames(bridge, frames: np.ndarray, period: float) -> None:
    """Publish ``frames`` every ``period`` seconds, no marks (a robot that records none)."""
    due = time.perf_counter()
    for frame in frames:
        bridge.publish_frame(frame)
        due += period
        if (wait := due - time.perf_counter()) > 0:
            time.sleep(wait)
