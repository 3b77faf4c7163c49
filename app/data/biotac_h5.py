"""BioTac trials in HDF5 files: ``read_biotac_h5`` and ``write_biotac_h5``, in the layout
``app.data.biotac``'s docstring describes."""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from app.data.biotac_errors import RawTrialError
from app.data.biotac_trial import CHANNELS, FingerSignals, RawTrial

_FINGER_GROUP = re.compile(r"finger_(\d+)")


def read_biotac_h5(path: str | Path | BinaryIO) -> dict[str, RawTrial]:
    """Every trial of one HDF5 file (a path, or a binary file object such as a request
    body in ``io.BytesIO``), ``{group name: RawTrial}`` in the file's group order.

    Errors are RawTrialError naming the file (when it has a path), the group, the finger
    and the channel.
    """
    import h5py

    if isinstance(path, str | Path):
        path = Path(path)
    where = str(path) if isinstance(path, Path) else None
    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise RawTrialError(f"cannot read as HDF5: {exc}", file=where) from None
    trials: dict[str, RawTrial] = {}
    with fh:
        for name, group in fh.items():
            if not isinstance(group, h5py.Group):
                continue  # a file-level array is not a trial
            try:
                trials[name] = _read_group(group)
            except RawTrialError as err:
                raise err.located(file=where, group=name) from None
            except (OSError, KeyError, TypeError) as exc:  # unreadable or truncated data
                raise RawTrialError(f"cannot read: {exc}", file=where, group=name) from None
    if not trials:
        raise RawTrialError("holds no trial group", file=where)
    return trials


def _read_group(group: Any) -> RawTrial:
    import h5py

    numbers = sorted(int(m.group(1)) for k in group if (m := _FINGER_GROUP.fullmatch(k)))
    if not numbers:
        raise RawTrialError("no finger group: a trial holds finger_0, finger_1, …")
    if numbers != list(range(len(numbers))):
        raise RawTrialError(
            f"finger groups must be numbered 0 … {len(numbers) - 1}, got "
            f"{', '.join(f'finger_{n}' for n in numbers)}"
        )
    fingers = []
    for i in numbers:
        node = group[f"finger_{i}"]
        if not isinstance(node, h5py.Group):
            raise RawTrialError(f"finger_{i} is not a group of channels", finger=i)
        channels = {}
        for key, ds in node.items():
            if not isinstance(ds, h5py.Dataset):
                raise RawTrialError("is a group, not a dataset", finger=i, channel=key)
            channels[key] = ds[()]
        try:
            fingers.append(FingerSignals.from_mapping(channels))
        except RawTrialError as err:
            raise err.located(finger=i) from None
    phases = group["phases"][()] if "phases" in group else None
    timestamps = group["timestamps"][()] if "timestamps" in group else None
    return RawTrial(fingers=tuple(fingers), phases=phases, timestamps=timestamps)


def write_biotac_h5(path: str | Path, trials: Mapping[str, RawTrial]) -> None:
    """Write trials, ``{group name: RawTrial}``, in the layout ``read_biotac_h5`` reads
    (channels as float32; ``phases`` and ``timestamps`` only where the trial has them).
    The file is replaced if it exists."""
    import h5py

    path = Path(path)
    if not trials:
        raise ValueError("write_biotac_h5 needs at least one trial")
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with h5py.File(tmp, "w") as fh:
            for name, trial in trials.items():
                if not isinstance(trial, RawTrial):
                    raise TypeError(f"trial {name!r} is a {type(trial).__name__}, not a RawTrial")
                group = fh.create_group(name)
                for i, finger in enumerate(trial.fingers):
                    sub = group.create_group(f"finger_{i}")
                    for channel in CHANNELS:
                        sub.create_dataset(
                            channel,
                            data=getattr(finger, channel),
                            compression="gzip",
                            compression_opts=4,
                        )
                if trial.phases is not None:
                    if any(p is None for p in trial.phases):
                        raise ValueError(
                            f"trial {name!r} lacks a phase; a recording keeps whole trials"
                        )
                    group.create_dataset("phases", data=np.asarray(trial.phases, dtype=np.int64))
                if trial.timestamps is not None:
                    group.create_dataset("timestamps", data=trial.timestamps)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
