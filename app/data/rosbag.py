"""ROS 2 bags of the bridge's topics as datasets: ``biotac:`` folders from raw frames and
procedure marks, ``folder:`` datasets from samples (``tactile-zsl dataset bag``).

A lab records with ``ros2 bag record`` (mcap or sqlite3); ``rosbags`` reads both without
ROS. Each bag is the recording of one object, named by the caller. Messages are taken in
the order of their recorded time:

- frames (``std_msgs/Float32MultiArray``, ``app.ros2.arrays``'s layout) and procedure marks
  (``std_msgs/String``) become trials exactly as the bridge assembles them
  (``app.ros2.trials.TrialAssembler``: a trial from its first procedure to ``end``, with
  the 100 frames before it as its rest and each procedure's ``[start, end)`` as a
  phase); every trial must hold every procedure. A bag with frames and no marks is one
  trial whose phases are found in its pdc (``PhaseRule``).
- samples (``std_msgs/Float32MultiArray`` with ``layout.dim``: one sample, or a leading
  count of several) become samples of that object, each message a trial of its own.

Errors name the bag, the topic and the message.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.data.biotac import RawTrial, RawTrialError, write_biotac_h5
from app.data.biotac_phases import PhaseRule
from app.data.contacts import ContactMarks
from app.data.dataset import DatasetError, TactileDataset

FRAMES, PROCEDURE, SAMPLES = "tactile_zsl/frames", "tactile_zsl/procedure", "tactile_zsl/samples"
DIAGNOSTICS = "/diagnostics"
DEFAULT_PROCEDURES = ("tap", "hold", "squeeze")


class BagError(DatasetError):
    """A bag that cannot become a dataset; the message names the bag, topic and message."""


@dataclass(frozen=True)
class Recording:
    """A bag and the object it recorded."""

    path: Path
    object: str

    @classmethod
    def parse(cls, text: str) -> Recording:
        """``OBJECT=PATH``."""
        name, sep, path = text.partition("=")
        if not sep or not name.strip() or not path:
            raise BagError(f"{text!r}: give each bag as OBJECT=PATH (e.g. cork=bags/cork_1)")
        return cls(Path(path), name.strip())


def find_topic(topics: Sequence[str], wanted: str) -> str | None:
    """The bag's topic named ``wanted``, or ending in ``/wanted`` (a namespaced bridge)."""
    exact = [t for t in topics if t == wanted or t == "/" + wanted.lstrip("/")]
    ending = [t for t in topics if t.endswith("/" + wanted.lstrip("/"))]
    found = exact or ending
    if len(found) > 1:
        raise BagError(f"several topics end in {wanted!r} ({', '.join(found)}); name one")
    return found[0] if found else None


def read_messages(
    path: Path, topics: Sequence[str]
) -> tuple[list[str], list[tuple[str, int, Any]]]:
    """The bag's topics, and the messages of ``topics`` (name or ending, see ``find_topic``) as
    (wanted topic, recorded time in ns, message) in recorded order."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise BagError(f"{path}: no bag there")
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_KILTED)) as reader:
            names = [c.topic for c in reader.connections]
            chosen = {w: find_topic(names, w) for w in topics}
            by_topic = {t: w for w, t in chosen.items() if t is not None}
            connections = [c for c in reader.connections if c.topic in by_topic]
            if not connections:  # rosbags reads every topic when given none
                return names, []
            out = [
                (by_topic[conn.topic], stamp, reader.deserialize(raw, conn.msgtype))
                for conn, stamp, raw in reader.messages(connections=connections)
            ]
    except BagError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own errors per format
        raise BagError(f"{path}: not a readable ROS 2 bag ({type(exc).__name__}: {exc})") from None
    out.sort(key=lambda m: m[1])
    return names, out


def bag_trials(
    path: Path, procedures: Sequence[str] = DEFAULT_PROCEDURES, rest_frames: int = 100
) -> list[RawTrial]:
    """The raw trials of one bag (frames and procedure marks, or frames alone)."""
    from app.ros2.arrays import MessageShapeError, frame_of
    from app.ros2.trials import END, MarkOrder, TrialAssembler, TrialProblem

    names, messages = read_messages(path, (FRAMES, PROCEDURE))
    frames = [(stamp, m) for topic, stamp, m in messages if topic == FRAMES]
    if not frames:
        raise BagError(f"{path}: no frames on a topic ending in {FRAMES!r} (topics: {names})")
    marks = [m for topic, _, m in messages if topic == PROCEDURE]
    # the bridge's own rule: marks placed among the frames by their stamps (MarkOrder),
    # here the bag's recorded times (rosbags reads no source stamps), then assembled; a bag
    # without marks is cut by contact as the bridge's contact_detection cuts (ContactMarks)
    assembler = TrialAssembler(rest_frames=rest_frames, max_frames=10**7)
    order = MarkOrder(wait=float("inf"))
    contacts = None if marks else ContactMarks(procedures, PhaseRule(len(procedures), rest_frames))
    trials: list[RawTrial] = []
    last: list[dict[str, Any] | None] = [None]

    def follow(mark: tuple[str, int], late: int) -> None:
        text, stamp = mark
        where = f"{path}: {PROCEDURE} message at {stamp} ns"
        if contacts is not None:
            where = f"{path}: contact mark {text!r} at the frame recorded at {stamp} ns"
        try:
            done = assembler.procedure(text, procedures, late)
        except TrialProblem as exc:
            raise BagError(f"{where}: {exc}") from None
        last[0] = done if done is not None else last[0]
        if text.strip() == END:
            if last[0] is None:
                raise BagError(f"{where}: the trial ended before any procedure was done")
            trials.append(_whole(last[0], procedures, f"{path}: trial {len(trials)}"))
            last[0] = None

    for topic, stamp, msg in messages:
        if topic == FRAMES:
            for mark in order.frame(stamp, 0.0):
                follow(mark, 0)
            try:
                frame = frame_of(msg)
            except MessageShapeError as exc:
                raise BagError(f"{path}: {topic} message at {stamp} ns: {exc}") from None
            for text, late in contacts.frame(frame) if contacts is not None else ():
                follow((text, stamp), late)
            assembler.frame(frame)
        else:
            for mark, late in order.mark((msg.data, stamp), stamp):
                follow(mark, late)
    for mark in order.drain():
        follow(mark, 0)
    for text, late in contacts.drain() if contacts is not None else ():
        follow((text, messages[-1][1]), late)
    if assembler.open and contacts is not None:
        raise BagError(
            f"{path}: the last trial has {contacts.done} of its {len(procedures)} contacts "
            f"({', '.join(procedures)}); it would be incomplete"
        )
    if assembler.open:
        raise BagError(f"{path}: the last trial has no 'end' mark; it would be incomplete")
    if not trials and contacts is not None:
        raise BagError(
            f"{path}: no contact found in finger 0's pdc (none rises "
            f"{contacts.rule.contact_counts:g} counts above its resting level); no trial to cut"
        )
    return trials


def _whole(trial: dict[str, Any], procedures: Sequence[str], where: str) -> RawTrial:
    missing = [p for p, phase in zip(procedures, trial["phases"], strict=True) if phase is None]
    if missing:
        raise BagError(
            f"{where} lacks {', '.join(missing)}; a dataset's trials hold every procedure "
            f"({', '.join(procedures)})"
        )
    try:
        return RawTrial(fingers=trial["fingers"], phases=trial["phases"])
    except RawTrialError as exc:
        raise BagError(f"{where}: {exc}") from None


def write_biotac_from_bags(
    recordings: Sequence[Recording],
    out: Path,
    procedures: Sequence[str] = DEFAULT_PROCEDURES,
    overwrite: bool = False,
) -> dict[str, int]:
    """A ``biotac:`` folder in ``out``: one HDF5 file per object, a group per trial named
    ``<bag>_<NN>``. Returns the trials written per object."""
    trials: dict[str, dict[str, RawTrial]] = {}
    for rec in recordings:
        groups = trials.setdefault(rec.object, {})
        for k, trial in enumerate(bag_trials(rec.path, procedures)):
            groups[f"{rec.path.stem}_{k + 1:02d}"] = trial
    out.mkdir(parents=True, exist_ok=True)
    clash = [o for o in trials if (out / f"{o}.h5").exists()]
    if clash and not overwrite:
        raise BagError(f"{out / (clash[0] + '.h5')} exists; pass --overwrite to replace it")
    for name, groups in trials.items():
        if not groups:
            raise BagError(f"no trial of {name!r} in its bags")
        write_biotac_h5(out / f"{name}.h5", groups)
    return {name: len(groups) for name, groups in trials.items()}


def recorded_procedures(messages: Sequence[tuple[str, int, Any]]) -> tuple[str, ...] | None:
    """The procedures the bridge's recorded ``/diagnostics`` name (its model's sample
    layout), the last recorded; None where the bag holds none."""
    found = None
    for topic, _, msg in messages:
        if topic != DIAGNOSTICS:
            continue
        for status in msg.status:
            if status.name.endswith("tactile_zsl: recognition"):
                values = {kv.key: kv.value for kv in status.values}
                if values.get("procedures"):
                    found = tuple(values["procedures"].split(","))
    return found


def samples_from_bags(
    recordings: Sequence[Recording], procedures: Sequence[str] | None = None
) -> TactileDataset:
    """The samples of the bags as a dataset: each message one trial of its bag's object.
    ``procedures``: the samples' procedure layout (``app.data.procedures``); None: the one
    the bridge's ``/diagnostics`` name where the bag recorded them, else none."""
    from app.ros2.arrays import MessageShapeError, array_of

    objects = list(dict.fromkeys(rec.object for rec in recordings))
    read: list[tuple[str, np.ndarray, int]] = []  # (where, array, label)
    layouts: set[tuple[str, ...]] = set()
    for rec in recordings:
        names, messages = read_messages(rec.path, (SAMPLES, DIAGNOSTICS))
        if (layout := recorded_procedures(messages)) is not None:
            layouts.add(layout)
        messages = [m for m in messages if m[0] == SAMPLES]
        if not messages:
            raise BagError(f"{rec.path}: no samples on a topic ending in {SAMPLES!r} ({names})")
        for _, stamp, msg in messages:
            where = f"{rec.path}: {SAMPLES} message at {stamp} ns"
            if not msg.layout.dim:
                raise BagError(f"{where}: no layout.dim, so its samples' shape is not known")
            try:
                read.append((where, array_of(msg), objects.index(rec.object)))
            except MessageShapeError as exc:
                raise BagError(f"{where}: {exc}") from None
    # a sample has the fewest dims; a message with one more holds several
    shape = min((x.shape for _, x, _ in read), key=len)
    samples, labels = [], []
    for where, x, label in read:
        batch = x[None] if x.shape == shape else x
        if batch.shape[1:] != shape:
            raise BagError(f"{where}: shape {list(x.shape)}, not {list(shape)} or N of them")
        if not np.isfinite(batch).all():
            raise BagError(f"{where}: NaN or infinite values; a dataset holds whole samples")
        samples += list(batch)
        labels += [label] * len(batch)
    if procedures is None and len(layouts) > 1:
        raise BagError(
            f"the bags' /diagnostics name several procedure layouts ({sorted(layouts)}); "
            "give --procedures"
        )
    if procedures is None:
        procedures = layouts.pop() if layouts else ()
    try:
        return TactileDataset(
            samples=np.stack(samples),
            labels=np.array(labels),
            trials=np.arange(len(samples)),
            class_attributes=np.zeros((len(objects), 0), np.float32),
            attribute_names=(),
            class_names=tuple(objects),
            name="bags",
            procedures=tuple(procedures),
        )
    except DatasetError as exc:
        raise BagError(f"samples of shape {list(shape)}: {exc}") from None
