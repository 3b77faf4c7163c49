"""How the store writes values down (attribute keys: ``app.store.vocabulary``): samples as
float32 bytes with their shape, raw trials as ``.npz``, metrics as strict JSON. No
queries."""

from __future__ import annotations

import io
import zipfile
from collections.abc import Sequence
from typing import Any

import numpy as np

from app.data.biotac import CHANNELS, RawTrial
from app.store.enums import SampleForm


def encode_sample(sample: np.ndarray) -> tuple[bytes, list[int]]:
    x = np.ascontiguousarray(sample, dtype=np.float32)
    return x.tobytes(), list(x.shape)


def decode_sample(data: bytes, shape: Sequence[int]) -> np.ndarray:
    return np.frombuffer(data, dtype=np.float32).reshape(tuple(shape))


def encode_trial(trial: RawTrial) -> bytes:
    """A raw trial as ``.npz`` bytes (no pickle): ``finger_<i>/<channel>`` arrays as
    validated (float32), and ``phases`` and ``timestamps`` when the trial has them."""
    arrays = {
        f"finger_{i}/{name}": getattr(finger, name)
        for i, finger in enumerate(trial.fingers)
        for name in CHANNELS
    }
    if trial.phases is not None:
        arrays["phases"] = np.asarray(trial.phases, dtype=np.int64)
    if trial.timestamps is not None:
        arrays["timestamps"] = trial.timestamps
    out = io.BytesIO()
    # np.savez_compressed's layout, deflated at level 1: raw counts shrink ~6x either way,
    # and level 1 takes a tenth of the time (an enrolment waits for it)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, array in arrays.items():
            with zf.open(f"{name}.npy", "w") as member:
                np.lib.format.write_array(member, np.asanyarray(array), allow_pickle=False)
    return out.getvalue()


def decode_trial(data: bytes) -> RawTrial:
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    n = 1 + max(int(k.split("/")[0].removeprefix("finger_")) for k in arrays if "/" in k)
    fingers = [{c: arrays[f"finger_{i}/{c}"] for c in CHANNELS} for i in range(n)]
    phases = arrays.get("phases")
    return RawTrial(
        fingers=fingers,
        phases=None if phases is None else [tuple(p) for p in phases.tolist()],
        timestamps=arrays.get("timestamps"),
    )


def encode(sample: np.ndarray | RawTrial) -> tuple[bytes, list[int], SampleForm]:
    """``(data, shape, form)`` of a sample row: an array, or a raw trial as it was sent."""
    if isinstance(sample, RawTrial):
        return encode_trial(sample), [], SampleForm.RAW_TRIAL
    data, shape = encode_sample(sample)
    return data, shape, SampleForm.ARRAY


def decode(row: Any) -> np.ndarray | RawTrial:
    """The sample of a row (anything with ``data``, ``shape`` and ``form``)."""
    if row.form == SampleForm.RAW_TRIAL:
        return decode_trial(row.data)
    return decode_sample(row.data, row.shape)
