"""``std_msgs/msg/Float32MultiArray`` to and from numpy, for samples and raw BioTac frames.

A message's ``layout.dim`` gives its shape (outermost first, as ROS documents it; ``stride``
is not needed for a dense array and is ignored) and ``layout.data_offset`` the values to
skip. A sample message with no ``dim`` is read as the model's input shape, or several
samples of it when it holds a multiple of that many values.

A raw BioTac frame is one row per finger of ``FRAME_WIDTH`` (44) values, in the order of
``FRAME_CHANNELS``: ``pdc``, ``tdc``, ``tac``, the 22 ``pac`` sub-samples, the 19
electrodes (the channels the BioTac driver publishes per finger, ``app.data.biotac``).
Its ``dim`` is ``[fingers, 44]`` (or ``[44]`` for one finger); with no ``dim``, every 44
values are one finger.
"""

from __future__ import annotations

import array
import math
from typing import Any

import numpy as np

from app.data.biotac import CHANNELS

#: the channels of one finger in a frame, and the columns each takes
FRAME_CHANNELS: dict[str, int] = {name: width or 1 for name, width in CHANNELS.items()}
FRAME_WIDTH = sum(FRAME_CHANNELS.values())  # 44


class MessageShapeError(ValueError):
    """A message whose values do not fill the shape its layout gives."""


def array_of(msg: Any) -> np.ndarray:
    """The message's values as float32, shaped by its ``layout.dim`` (flat without one)."""
    data = np.asarray(msg.data, dtype=np.float32)[int(msg.layout.data_offset) :]
    dims = msg.layout.dim
    if not dims:
        return data
    shape = tuple(int(d.size) for d in dims)
    if math.prod(shape) != data.size:
        raise MessageShapeError(
            f"layout.dim gives shape {list(shape)} ({math.prod(shape)} values), "
            f"the message holds {data.size}"
        )
    return data.reshape(shape)


def samples_of(msg: Any, input_shape: tuple[int, ...] | None) -> np.ndarray:
    """A sample message as one sample or a batch; a flat message of a multiple of the
    model's sample size is that many samples (``input_shape`` None: as it came)."""
    x = array_of(msg)
    if msg.layout.dim or not input_shape:
        return x
    size = math.prod(input_shape)
    if x.size == size:
        return x.reshape(input_shape)
    if x.size and x.size % size == 0:
        return x.reshape(-1, *input_shape)
    return x


def frame_of(msg: Any) -> np.ndarray:
    """A raw frame message as (fingers, FRAME_WIDTH) float32."""
    x = array_of(msg)
    if x.ndim == 1 and x.size and x.size % FRAME_WIDTH == 0:
        return x.reshape(-1, FRAME_WIDTH)
    if x.ndim == 2 and x.shape[1] == FRAME_WIDTH and len(x):
        return x
    raise MessageShapeError(
        f"a frame is one row of {FRAME_WIDTH} values per finger ({', '.join(FRAME_CHANNELS)}), "
        f"got shape {list(x.shape)}"
    )


def fingers_of(frames: np.ndarray) -> list[dict[str, np.ndarray]]:
    """(T, fingers, FRAME_WIDTH) frames as the fingers of a trial's JSON form."""
    fingers = []
    for f in range(frames.shape[1]):
        finger, start = {}, 0
        for name, width in FRAME_CHANNELS.items():
            block = frames[:, f, start : start + width]
            finger[name] = block[:, 0] if CHANNELS[name] is None else block
            start += width
        fingers.append(finger)
    return fingers


def frames_of(trial: Any) -> np.ndarray:
    """A ``RawTrial``'s signals as (T, fingers, FRAME_WIDTH) frames, as a driver publishes."""
    per_finger = [
        np.column_stack(
            [
                np.asarray(getattr(finger, name), np.float32).reshape(finger.n_frames, -1)
                for name in FRAME_CHANNELS
            ]
        )
        for finger in trial.fingers
    ]
    return np.stack(per_finger, axis=1)


def multiarray(x: Any, labels: tuple[str, ...] | None = None) -> Any:
    """A ``Float32MultiArray`` of ``x`` with its shape in ``layout.dim`` (for publishers:
    the tests, the benchmark, a robot's own code)."""
    from std_msgs.msg import Float32MultiArray, MultiArrayDimension

    x = np.ascontiguousarray(x, dtype=np.float32)
    labels = labels or tuple(f"dim{i}" for i in range(x.ndim))
    msg = Float32MultiArray()
    strides = [math.prod(x.shape[i:]) for i in range(x.ndim)]
    msg.layout.dim = [
        MultiArrayDimension(label=label, size=int(size), stride=int(stride))
        for label, size, stride in zip(labels, x.shape, strides, strict=True)
    ]
    values = array.array("f")
    values.frombytes(x.tobytes())  # what rclpy keeps a float32[] in: no copy per value
    msg.data = values
    return msg


def header_of(value: Any) -> dict[str, Any]:
    """A ``std_msgs/Header`` as JSON (``{"stamp": {"sec", "nanosec"}, "frame_id"}``),
    checked; MessageShapeError naming what is wrong."""
    if not isinstance(value, dict):
        raise MessageShapeError("header: an object {stamp: {sec, nanosec}, frame_id} is needed")
    stamp = value.get("stamp", {"sec": 0, "nanosec": 0})
    if not isinstance(stamp, dict) or set(stamp) != {"sec", "nanosec"}:
        raise MessageShapeError("header.stamp: an object {sec, nanosec} is needed")
    sec, nanosec = stamp["sec"], stamp["nanosec"]
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (sec, nanosec)) or not (
        0 <= nanosec < 10**9
    ):
        raise MessageShapeError(
            f"header.stamp: integers sec and nanosec in [0, 1e9) are needed, got {stamp}"
        )
    frame_id = value.get("frame_id", "")
    if not isinstance(frame_id, str):
        raise MessageShapeError(f"header.frame_id: a string is needed, got {frame_id!r}")
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}


def stamped_of(text: str) -> tuple[np.ndarray, dict[str, Any], list[Any] | None]:
    """A ``~/samples_stamped`` message's JSON, ``{"header": {...}, "samples": [...]}``: the
    samples (nested lists, one sample or several), the robot's header, and the optional
    ``objects``, a table's label of each sample's object (docs/TABLES.md; None without)."""
    import json

    try:
        body = json.loads(text)
    except ValueError as exc:
        raise MessageShapeError(f"body: malformed JSON: {exc}") from None
    if not isinstance(body, dict) or "samples" not in body or "header" not in body:
        raise MessageShapeError("body: an object {header, samples} is needed")
    header = header_of(body["header"])
    try:
        x = np.asarray(body["samples"], dtype=np.float32)
    except (TypeError, ValueError):
        raise MessageShapeError(
            "samples: nested lists of numbers of one shape are needed"
        ) from None
    objects = body.get("objects")
    if objects is not None and not isinstance(objects, list):
        raise MessageShapeError("objects: a list of labels, one per sample, is needed")
    return x, header, objects
