"""Raw BioTac trials as a recognizer's input.

A recognizer fitted on fixed-shape samples takes samples (``input_kind == SAMPLES``); one
fitted on raw trials keeps the featurizer it fitted and takes trials (``input_kind ==
RAW_TRIALS``). ``trial_images`` turns trials into such a model's samples, one tactile
image per finger; ``looks_like_trials`` tells trials given where samples belong, and
``takes_samples`` / ``takes_trials`` say in errors which input a model takes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from app.data.biotac import RawTrial, RawTrialError, parse_trial
from app.framework.errors import InputKindError, InputShapeError, TrialInputError

#: ``input_kind`` of a model fitted on fixed-shape samples / on raw BioTac trials
SAMPLES = "samples"
RAW_TRIALS = "raw_trials"


def takes_samples(input_shape: tuple[int, ...]) -> str:
    """What a model of fixed-shape samples takes, for an error message."""
    shape = ", ".join(map(str, input_shape))
    return f"this model takes fixed-shape samples of shape (N, {shape})"


def takes_trials(input_shape: tuple[int, ...]) -> str:
    """What a model fitted on raw trials takes, for an error message."""
    shape = ", ".join(map(str, input_shape))
    return (
        "this model was fitted on raw BioTac trials and takes raw trials "
        "(recognize_trials, attribute_proba_trials; trial_samples turns trials into its "
        f"samples, the tactile images of shape (N, {shape}), one per finger)"
    )


def trial_images(featurizer: Any, trials: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(images, trial_index)`` of raw ``trials`` (a ``RawTrial``, its JSON form or a list
    of them) made by a fitted ``featurizer``: float32 images, every trial's fingers in
    order, and the int64 index of each image's trial. Errors as
    ``TactileRecognizer.trial_samples``."""
    if isinstance(trials, RawTrial | Mapping):
        trials = [trials]
    if isinstance(trials, str | bytes) or not isinstance(trials, Sequence):
        raise InputKindError(
            f"expected a raw trial or a list of raw trials, got {type(trials).__name__}"
        )
    if len(trials) == 0:
        raise InputShapeError("expected at least one trial, got an empty list")
    try:
        parsed = [parse_trial(t, trial=i, check_phases=False) for i, t in enumerate(trials)]
        images = featurizer.transform(parsed)
    except RawTrialError as err:
        raise TrialInputError(
            str(err),
            reason=err.reason,
            trial=err.trial,
            finger=err.finger,
            channel=err.channel,
        ) from err
    index = np.repeat(np.arange(len(parsed), dtype=np.int64), [t.n_fingers for t in parsed])
    return images.astype(np.float32, copy=False), index


def looks_like_trials(samples: Any) -> bool:
    """A RawTrial, a trial's JSON form, or a list whose first item is one of those."""
    if isinstance(samples, RawTrial) or (isinstance(samples, Mapping) and "fingers" in samples):
        return True
    if isinstance(samples, list | tuple) and samples:
        return looks_like_trials(samples[0])
    return False
