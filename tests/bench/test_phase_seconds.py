"""bench/phase_seconds.py: the pilot's phase lengths, the source of the robot times that
``app.data.procedures.SECONDS`` gives tap and squeeze."""

import json

import pytest

from app.data.procedures import SECONDS
from bench import phase_seconds
from tests.framework.raw_data import pilot_path


def test_the_pilots_phases_give_the_robot_times_of_tap_and_squeeze(capsys):
    path = pilot_path()
    assert phase_seconds.main(["--data", str(path)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["trials"] == 74
    assert 95 < report["frame_rate_hz"]["median"] < 105  # about 100 Hz, as the README says
    phases = report["phases"]
    assert phases["tap"]["median"] == SECONDS["tap"]
    assert round(phases["squeeze"]["median"], 1) == SECONDS["squeeze"]
    assert phases["hold"]["median"] == 16.93  # the figure --durations hold=16.93 gives
    for q in phases.values():
        assert q["q25"] <= q["median"] <= q["q75"]


def test_a_missing_folder_exits_2(tmp_path):
    with pytest.raises(SystemExit) as done:
        phase_seconds.main(["--data", str(tmp_path / "none")])
    assert done.value.code == 2
