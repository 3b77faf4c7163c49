"""Contact detection (``app.data.contacts``) on every real pilot recording, frame by frame
as the bridge hears it: three contacts per trial, each within ``CONTACT_TOLERANCE``
frames of the phases ``PhaseRule`` finds in the whole recording (where the replays put
their procedure marks)."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.biotac import read_biotac_h5
from app.data.contacts import END, REST, ContactMarks
from app.ros2.arrays import frames_of

from .conftest import PILOT
from .test_bags import CONTACT_TOLERANCE

PROCEDURES = ("tap", "hold", "squeeze")


def cut(frames: np.ndarray) -> list[tuple[str, int]]:
    """Each mark ContactMarks gives, with the frame it falls before."""
    marks, contacts = [], ContactMarks(PROCEDURES)
    for k, frame in enumerate(frames):
        marks += [(name, k - late) for name, late in contacts.frame(frame)]
    return marks + [(name, len(frames) - late) for name, late in contacts.drain()]


def test_every_pilot_trial_is_cut_into_its_three_phases():
    files = sorted(PILOT.glob("*.h5"))
    if not files:
        pytest.skip(f"BioTac pilot data not found at {PILOT.resolve()}")
    worst, n = 0, 0
    for path in files:
        for name, trial in sorted(read_biotac_h5(path).items()):
            frames, phases = frames_of(trial), trial.phase_bounds()[0]
            first = max(0, phases[0][0] - 150)  # the replays' lead-in of rest
            marks = cut(frames[first : phases[-1][1] + 10])
            expected = [
                (PROCEDURES[i // 2] if i % 2 == 0 else REST, b - first)
                for i, b in enumerate(np.ravel(phases))
            ]
            assert [m for m, _ in marks] == [m for m, _ in expected] + [END], name
            gaps = [abs(a - b) for (_, a), (_, b) in zip(marks, expected, strict=False)]
            worst, n = max(worst, *gaps), n + 1
    assert n == 74 and worst <= CONTACT_TOLERANCE


def test_a_twitch_shorter_than_min_frames_starts_no_contact():
    frames = np.zeros((400, 2, 44), np.float32)
    frames[150:152, :, 0] = 200.0  # two frames: under PhaseRule's min_frames of 3
    frames[200:260, :, 0] = 200.0
    assert cut(frames) == [("tap", 200), (REST, 260)]


def test_contact_detection_needs_procedures():
    with pytest.raises(ValueError, match="needs the model's procedures"):
        ContactMarks(())
