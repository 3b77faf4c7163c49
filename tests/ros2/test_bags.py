"""ROS 2 bags to datasets: bags written as ``ros2 bag record`` writes them (the messages the
robot publishes, serialized by rclpy, in mcap and sqlite3) from the real BioTac pilot
recordings, read by ``tactile-zsl dataset bag`` into ``biotac:`` and ``folder:`` datasets
that hold exactly the recorded frames, phases and samples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import String

from app.cli import main
from app.data.biotac import load_biotac, read_biotac_h5
from app.data.folder import load_folder
from app.ros2.arrays import fingers_of, frames_of, multiarray

from .conftest import PILOT

ARRAY, TEXT = "std_msgs/msg/Float32MultiArray", "std_msgs/msg/String"
NS = "/left_hand/tactile_zsl"
#: frames a contact-cut boundary may lie from PhaseRule's: the most over all 74 pilot
#: trials (tests/ros2/test_contacts.py), from the resting level taken before the contact
CONTACT_TOLERANCE = 2


def write_bag(path: Path, messages: list[tuple[str, str, int, object]], storage: str) -> Path:
    """A rosbag2 bag of (topic, type, time in ns, rclpy message)."""
    typestore = get_typestore(Stores.ROS2_KILTED)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {}
        for topic, msgtype, stamp, msg in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=typestore)
            writer.write(connections[topic], stamp, serialize_message(msg))
    return path


def recorded(trials, marks: bool = True, start_ns: int = 10**18):
    """The messages of a robot replaying ``trials`` at 100 Hz with procedure marks, and
    the trial the bag should give for each (frames from 100 before its first phase)."""
    messages, expected, t = [], [], start_ns
    for trial in trials:
        frames = frames_of(trial)
        phases = trial.phase_bounds()[0]
        mark_at = {}
        for (s, e), name in zip(phases, ("tap", "hold", "squeeze"), strict=True):
            mark_at[s], mark_at[e] = name, "rest"
        for k, frame in enumerate(frames):
            if marks and k in mark_at:
                messages.append((f"{NS}/procedure", TEXT, t - 1000, String(data=mark_at[k])))
            messages.append((f"{NS}/frames", ARRAY, t, multiarray(frame)))
            t += 10_000_000
        if marks:
            messages.append((f"{NS}/procedure", TEXT, t, String(data="end")))
        origin = phases[0][0] - 100
        expected.append(
            (frames[origin : phases[-1][1]], [[s - origin, e - origin] for s, e in phases])
        )
        t += 10**9
    return messages, expected


@pytest.fixture(scope="module")
def pilot_trials():
    if not (PILOT / "cork.h5").is_file():
        pytest.skip(f"BioTac pilot data not found at {PILOT.resolve()}")
    return {
        name: [t for _, t in sorted(read_biotac_h5(PILOT / f"{name}.h5").items())[:2]]
        for name in ("cork", "metal_bar")
    }


def test_bags_of_frames_and_marks_become_a_biotac_dataset_of_those_trials(
    pilot_trials, tmp_path, capsys
):
    bags, expected = [], {}
    for name, storage in (("cork", "mcap"), ("metal_bar", "sqlite3")):
        messages, expected[name] = recorded(pilot_trials[name])
        bags.append(f"{name}={write_bag(tmp_path / name, messages, storage)}")
    out = tmp_path / "dataset"
    assert main(["dataset", "bag", "--out", str(out), *bags]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["spec"] == f"biotac:{out}" and summary["trials"] == 4
    assert summary["object_names"] == ["cork", "metal_bar"]

    dataset = load_biotac(out)
    for trial, label in zip(dataset.trials, dataset.labels, strict=True):
        frames, phases = expected[dataset.class_names[label]].pop(0)
        assert [list(p) for p in trial.phases] == phases
        for got, want in zip(trial.fingers, fingers_of(frames), strict=True):
            for channel, values in want.items():
                assert np.array_equal(getattr(got, channel), values), channel


def test_a_bag_of_frames_alone_is_cut_into_trials_by_contact(pilot_trials, tmp_path):
    """Two recordings one after the other, no marks: two trials, each cut where its
    contacts are (``ContactMarks``), within ``CONTACT_TOLERANCE`` frames of the phases
    ``PhaseRule`` finds in the whole recording, with the recorded frames."""
    messages, _ = recorded(pilot_trials["cork"], marks=False)
    bag = write_bag(tmp_path / "cork_touch", messages, "mcap")
    out = tmp_path / "dataset"
    assert main(["dataset", "bag", "--out", str(out), f"cork={bag}"]) == 0
    got = load_biotac(out).trials
    assert len(got) == len(pilot_trials["cork"])
    for trial, source in zip(got, pilot_trials["cork"], strict=True):
        cut, phases = [list(p) for p in trial.phases], source.phase_bounds()[0]
        assert cut[0][0] == 100  # the rest before the first contact, as with marks
        # the recorded frames, from where the contact cut begins near PhaseRule's
        near = range(phases[0][0] - 100 - CONTACT_TOLERANCE, phases[0][0] - 99 + CONTACT_TOLERANCE)
        length, recorded_frames = len(frames_of(trial)), frames_of(source)
        (origin,) = [
            o for o in near if np.array_equal(frames_of(trial), recorded_frames[o : o + length])
        ]
        for (s, e), (ms, me) in zip(cut, phases, strict=True):
            assert abs(origin + s - ms) <= CONTACT_TOLERANCE, (origin, cut, phases)
            assert abs(origin + e - me) <= CONTACT_TOLERANCE, (origin, cut, phases)


def test_a_bag_of_frames_alone_whose_contacts_stop_short_is_refused(pilot_trials, tmp_path, capsys):
    messages, expected = recorded(pilot_trials["cork"][:1], marks=False)
    hold_end = expected[0][1][1][1] + pilot_trials["cork"][0].phase_bounds()[0][0][0] - 100
    bag = write_bag(tmp_path / "cut_short", messages[: hold_end + 30], "mcap")
    assert main(["dataset", "bag", "--out", str(tmp_path / "out"), f"cork={bag}"]) == 2
    assert "the last trial has 2 of its 3 contacts" in capsys.readouterr().err


def test_bags_of_samples_become_a_folder_dataset(tmp_path, capsys):
    rng = np.random.default_rng(0)
    touches = {name: rng.normal(size=(3, 8, 30)).astype(np.float32) for name in ("cup", "foam")}
    bags = []
    for name, x in touches.items():
        messages = [(f"{NS}/samples", ARRAY, 10**18 + k, multiarray(s)) for k, s in enumerate(x)]
        messages.append((f"{NS}/samples", ARRAY, 10**18 + 9, multiarray(x[:2])))  # a batch
        bags.append(f"{name}={write_bag(tmp_path / name, messages, 'sqlite3')}")
    out = tmp_path / "dataset"
    assert main(["dataset", "bag", "--out", str(out), *bags]) == 0
    assert json.loads(capsys.readouterr().out)["spec"] == f"folder:{out}"
    dataset = load_folder(out)
    want = np.concatenate([np.concatenate([x, x[:2]]) for x in touches.values()])
    assert np.array_equal(dataset.samples, want)
    assert [dataset.class_names[i] for i in dataset.labels] == ["cup"] * 5 + ["foam"] * 5
    assert len(np.unique(dataset.trials)) == 10


def test_bags_that_cannot_become_a_dataset_are_refused_by_name(pilot_trials, tmp_path, capsys):
    messages, _ = recorded(pilot_trials["cork"][:1])
    unended = write_bag(tmp_path / "unended", messages[:-1], "mcap")
    out = str(tmp_path / "out")
    assert main(["dataset", "bag", "--out", out, f"cork={unended}"]) == 2
    assert "the last trial has no 'end' mark" in capsys.readouterr().err
    no_hold = [m for m in messages if not (m[1] == TEXT and m[3].data == "hold")]
    partial = write_bag(tmp_path / "no_hold", no_hold, "mcap")
    assert main(["dataset", "bag", "--out", out, f"cork={partial}"]) == 2
    assert "trial 0 lacks hold" in capsys.readouterr().err
    assert main(["dataset", "bag", "--out", out, str(unended)]) == 2
    assert "give each bag as OBJECT=PATH" in capsys.readouterr().err
    assert main(["dataset", "bag", "--out", out, f"cork={tmp_path / 'nowhere'}"]) == 2
    assert "no bag there" in capsys.readouterr().err


def test_bags_of_samples_keep_the_procedure_layout_the_bridge_named(tmp_path, capsys):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    status = DiagnosticStatus(name=f"{NS}: recognition")
    status.values = [KeyValue(key="procedures", value="squeeze,hold,slide,move_down")]
    diagnostics = ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", 10**18 - 5)
    x = np.random.default_rng(1).normal(size=(2, 8, 30)).astype(np.float32)
    messages = [(*diagnostics, DiagnosticArray(status=[status]))]
    messages += [(f"{NS}/samples", ARRAY, 10**18 + k, multiarray(s)) for k, s in enumerate(x)]
    bag = write_bag(tmp_path / "cup", messages, "mcap")
    out = tmp_path / "dataset"
    assert main(["dataset", "bag", "--out", str(out), f"cup={bag}"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["procedures"] == ["squeeze", "hold", "slide", "move_down"]
    assert load_folder(out).procedures == ("squeeze", "hold", "slide", "move_down")

    # a layout given that the samples' 8 rows cannot hold is refused by name
    again = str(tmp_path / "again")
    assert main(["dataset", "bag", "--out", again, "--procedures", "a,b,c", f"cup={bag}"]) == 2
    assert "samples of shape [8, 30]" in capsys.readouterr().err
