"""Raw BioTac trials on the wire: JSON (``{"trials": [...]}``, or one ``"trial"``) and, for
high-rate robots, HDF5 in the layout the BioTac recordings use (one group per trial with
``finger_0``, ``finger_1``, … groups of channels; ``docs/DATASETS.md``).

A malformed trial is a 422 naming the trial, the finger and the channel, e.g. the field
``trials[2].fingers[1].pac``; nothing is stored."""

from __future__ import annotations

import io
from typing import Any

from app.api.problems import Problem
from app.data.biotac import RawTrial, RawTrialError, parse_trial, read_biotac_h5

HDF5 = "application/x-hdf5"


def refused(input_shape: tuple[int, ...], field: str) -> Problem:
    """The 409 of raw trials sent to a model of samples, before they are read: what it
    takes instead."""
    return Problem(
        409,
        f"this model takes samples of shape {list(input_shape)} (`input_kind` `samples` of "
        'GET /v1/models/active), not raw BioTac trials: send {"samples": [...]} (or a .npy '
        "body); a model fitted on raw trials takes them (`--dataset biotac:DIR`)",
        field,
    )


def field_of(err: RawTrialError, prefix: str) -> str:
    """Where in the request a trial error is: ``trials[2].fingers[1].pac``."""
    place = prefix if err.trial is None else f"{prefix}[{err.trial}]"
    if err.group is not None:
        place = f"{prefix}[{err.group!r}]"
    if err.finger is not None:
        place += f".fingers[{err.finger}]"
    if err.channel is not None:
        place += f".{err.channel}"
    return place


def parse(data: Any, batch_limit: int) -> list[RawTrial]:
    """``data["trials"]`` of a JSON body as validated trials (at most ``batch_limit``)."""
    trials = data.get("trials") if isinstance(data, dict) else None
    if not isinstance(trials, list) or not trials:
        raise Problem(422, "'trials' must be a non-empty list of trials", "trials")
    if len(trials) > batch_limit:
        raise Problem(
            422,
            f"{len(trials)} trials is more than the batch limit of {batch_limit}: send at most "
            f"{batch_limit} a request, or raise TACTILE_BATCH_LIMIT on the service",
            "trials",
        )
    extra = set(data) - {"trials"}
    if extra:
        raise Problem(422, f"not a field of this request: {sorted(extra)[0]!r}", sorted(extra)[0])
    return [one(t, "trials", i) for i, t in enumerate(trials)]


def one(
    data: Any, prefix: str = "trial", index: int | None = None, whole: bool = False
) -> RawTrial:
    """One trial's JSON form, validated; a 422 naming its place otherwise. ``whole``: every
    phase must be there (enrolment learns from whole trials; recognition answers from
    the phases a trial holds)."""
    try:
        trial = parse_trial(data, trial=index)
    except RawTrialError as err:
        raise Problem(422, str(err), field_of(err, prefix)) from None
    if whole and trial.phases is not None and None in trial.phases:
        place = prefix if index is None else f"{prefix}[{index}]"
        missing = ", ".join(str(k) for k, p in enumerate(trial.phases) if p is None)
        raise Problem(
            422,
            f"phase(s) {missing} are null: a class learns from whole trials; send every phase",
            f"{place}.phases",
        )
    return trial


def from_hdf5(body: bytes, batch_limit: int) -> list[RawTrial]:
    """The trials of an HDF5 body, in the file's group order."""
    try:
        trials = list(read_biotac_h5(io.BytesIO(body)).values())
    except RawTrialError as err:
        raise Problem(422, str(err), field_of(err, "trials")) from None
    if len(trials) > batch_limit:
        raise Problem(
            422,
            f"{len(trials)} trials is more than the batch limit of {batch_limit}: send at most "
            f"{batch_limit} a request, or raise TACTILE_BATCH_LIMIT on the service",
            "trials",
        )
    try:
        for i, t in enumerate(trials):
            parse_trial(t, trial=i)  # phases must be findable, as for JSON trials
    except RawTrialError as err:
        raise Problem(422, str(err), field_of(err, "trials")) from None
    return trials
