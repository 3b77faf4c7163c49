"""Raw BioTac trials: the signals as recorded, validated, read from and written to HDF5.

A trial is one exploration of an object by a gripper with one or more BioTac fingers (two
on the PR2). Per finger it holds the channels of the BioTac ROS driver, named as there and
in the HDF5 files of ``../shared/data/biotac_pilot`` (T frames, any T >= 2):

=============  ========  ==========================================================
channel        shape     meaning
=============  ========  ==========================================================
``pdc``        (T,)      DC pressure
``tdc``        (T,)      DC temperature
``tac``        (T,)      AC temperature (heat flow)
``pac``        (T, 22)   AC pressure (vibration), 22 sub-samples per frame
``electrodes`` (T, 19)   impedance of the 19 electrodes
=============  ========  ==========================================================

The fingers of one trial are recorded together: they have the same number of frames.
A trial may carry its exploration phases as ``[start, end)`` frame ranges shared by its
fingers, and the frames' timestamps; without phases they are found in each finger's
``pdc`` by a ``PhaseRule`` (see its docstring and docs/DATASETS.md).

Every problem with a trial raises ``RawTrialError``, whose message and attributes name the
trial index (or file and group), the finger and the channel.

The HDF5 layout (read by ``read_biotac_h5``, written by ``write_biotac_h5``): one group per
trial holding ``finger_0`` … ``finger_<F-1>`` groups with one dataset per channel, and
optionally ``timestamps`` (T,) and ``phases`` (P, 2) next to them. The pilot's files are
PyTables files of that layout without ``phases``; other members of a trial group (other
sensors a recording may carry) are ignored.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from app.data.dataset import DatasetError, DatasetFileError

PAC_SUBSAMPLES = 22
N_ELECTRODES = 19
#: channel name -> number of columns (None: a 1-D series of one value per frame)
CHANNELS: dict[str, int | None] = {
    "pdc": None,
    "tdc": None,
    "tac": None,
    "pac": PAC_SUBSAMPLES,
    "electrodes": N_ELECTRODES,
}
MIN_FRAMES = 2
_TRIAL_FIELDS = ("fingers", "phases", "timestamps")
_FINGER_GROUP = re.compile(r"finger_(\d+)")
_PRESSURE = re.compile(r"_pdc(\d+(?:\.\d+)?)(?:_|$)")
H5_SUFFIXES = (".h5", ".hdf5")
OBJECTS_FILE = "objects.csv"


class RawTrialError(DatasetError):
    """A raw trial is malformed. ``trial`` (index in a batch), ``file`` and ``group`` (where
    it was read from), ``finger`` (index) and ``channel`` say where, ``reason`` what; those
    that do not apply are None, and the message names all that are set."""

    def __init__(
        self,
        reason: str,
        *,
        trial: int | None = None,
        finger: int | None = None,
        channel: str | None = None,
        file: str | None = None,
        group: str | None = None,
    ) -> None:
        self.reason, self.trial, self.finger, self.channel = reason, trial, finger, channel
        self.file, self.group = (None if file is None else str(file)), group
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.group is not None:
            where.append(f"group {self.group!r}")
        if self.trial is not None:
            where.append(f"trial {self.trial}")
        if self.finger is not None:
            where.append(f"finger {self.finger}")
        if self.channel is not None:
            where.append(f"channel {self.channel!r}")
        return f"{', '.join(where)}: {self.reason}" if where else self.reason

    def located(self, **where: Any) -> RawTrialError:
        """The same error with more of its location filled in (fields already set stay)."""
        fields = {k: getattr(self, k) for k in ("trial", "finger", "channel", "file", "group")}
        fields.update({k: v for k, v in where.items() if fields.get(k) is None})
        return RawTrialError(self.reason, **fields)


def _numbers(value: Any, channel: str) -> np.ndarray:
    """``value`` as a float32 array; RawTrialError unless it is numeric and rectangular."""
    try:
        raw = np.asarray(value)
    except ValueError:  # ragged nested lists
        raise RawTrialError("rows have different lengths", channel=channel) from None
    if raw.dtype == object:  # None (JSON null) or text among numbers
        raise RawTrialError("values must all be numbers (null or text among them)", channel=channel)
    if raw.dtype.kind not in "iuf":
        raise RawTrialError(f"values must be numbers, got {raw.dtype.name} values", channel=channel)
    with np.errstate(over="ignore"):
        return np.asarray(raw, dtype=np.float32)


def _check_finite(x: np.ndarray, channel: str) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        frame = int(np.argwhere(bad)[0][0])
        what = "NaN" if np.isnan(x.reshape(len(x), -1)[frame]).any() else "infinite"
        raise RawTrialError(
            f"frame {frame} is {what} (or too large for float32); signals must be finite",
            channel=channel,
        )


@dataclass(frozen=True, eq=False)
class FingerSignals:
    """The five channels of one BioTac finger over T frames (float32, validated)."""

    pdc: np.ndarray
    tdc: np.ndarray
    tac: np.ndarray
    pac: np.ndarray
    electrodes: np.ndarray

    def __post_init__(self) -> None:
        n_frames = None
        for name, width in CHANNELS.items():
            x = _numbers(getattr(self, name), name)
            if width is None and x.ndim != 1:
                raise RawTrialError(
                    f"expected one value per frame (shape (T,)), got shape {x.shape}", channel=name
                )
            if width is not None and (x.ndim != 2 or x.shape[1] != width):
                got = f"{x.shape[1]} columns" if x.ndim == 2 else f"shape {x.shape}"
                raise RawTrialError(
                    f"expected {width} columns per frame (shape (T, {width})), got {got}",
                    channel=name,
                )
            if n_frames is None:
                n_frames = len(x)
            elif len(x) != n_frames:
                raise RawTrialError(
                    f"has {len(x)} frames where 'pdc' has {n_frames}; every channel of a "
                    "finger needs one row per frame",
                    channel=name,
                )
            _check_finite(x, name)
            object.__setattr__(self, name, x)
        if n_frames < MIN_FRAMES:
            raise RawTrialError(
                f"the finger is too short: {n_frames} frame(s), at least {MIN_FRAMES} are needed",
                channel="pdc",
            )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> FingerSignals:
        """A finger from ``{"pdc": …, "tdc": …, "tac": …, "pac": …, "electrodes": …}``
        (lists or arrays); a missing, misnamed or extra channel is a RawTrialError."""
        if isinstance(data, FingerSignals):
            return data
        if not isinstance(data, Mapping):
            raise RawTrialError(
                f"a finger must be an object of channels {list(CHANNELS)}, "
                f"got {type(data).__name__}"
            )
        for key in data:
            if key not in CHANNELS:
                close = difflib.get_close_matches(str(key), list(CHANNELS), n=1, cutoff=0.5)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise RawTrialError(
                    f"unknown channel{hint}; the channels are {', '.join(CHANNELS)}",
                    channel=str(key),
                )
        for name in CHANNELS:
            if name not in data:
                raise RawTrialError("missing channel", channel=name)
        return cls(**{name: data[name] for name in CHANNELS})

    @property
    def n_frames(self) -> int:
        return len(self.pdc)

    def to_dict(self) -> dict[str, list]:
        """The channels as JSON-ready lists (what ``from_mapping`` reads)."""
        return {name: getattr(self, name).tolist() for name in CHANNELS}


@dataclass(frozen=True, eq=False)
class RawTrial:
    """One exploration: its fingers' signals, and optionally its phases and timestamps.

    fingers: one ``FingerSignals`` per finger (or a mapping of channels each), all with
        the same number of frames T.
    phases: ``[start, end)`` frame ranges of the exploration phases, in time order, shared
        by the fingers; None: found from each finger's pdc by a ``PhaseRule``.
    timestamps: (T,) time of each frame, kept as given (not used by the features).
    """

    fingers: tuple[FingerSignals, ...]
    phases: tuple[tuple[int, int], ...] | None = None
    timestamps: np.ndarray | None = None

    def __post_init__(self) -> None:
        fingers = self.fingers
        if isinstance(fingers, Mapping | str | bytes) or not isinstance(fingers, Sequence):
            raise RawTrialError(
                f"'fingers' must be a list of fingers, got {type(fingers).__name__}"
            )
        if len(fingers) == 0:
            raise RawTrialError("'fingers' is empty; a trial needs at least one finger")
        parsed = []
        for i, finger in enumerate(fingers):
            try:
                parsed.append(FingerSignals.from_mapping(finger))
            except RawTrialError as err:
                raise err.located(finger=i) from None
        n = parsed[0].n_frames
        for i, finger in enumerate(parsed[1:], start=1):
            if finger.n_frames != n:
                raise RawTrialError(
                    f"has {finger.n_frames} frames where finger 0 has {n}; the "
                    "fingers of a trial are recorded together",
                    finger=i,
                    channel="pdc",
                )
        object.__setattr__(self, "fingers", tuple(parsed))
        if self.timestamps is not None:
            ts = _numbers(self.timestamps, "timestamps").astype(np.float64)
            if ts.shape != (n,):
                raise RawTrialError(
                    f"expected shape ({n},), one time per frame, got {ts.shape}",
                    channel="timestamps",
                )
            _check_finite(ts, "timestamps")
            object.__setattr__(self, "timestamps", ts)
        if self.phases is not None:
            object.__setattr__(self, "phases", _phases(self.phases, n))

    @property
    def n_frames(self) -> int:
        return self.fingers[0].n_frames

    @property
    def n_fingers(self) -> int:
        return len(self.fingers)

    def phase_bounds(
        self, rule: PhaseRule | None = None
    ) -> tuple[tuple[tuple[int, int], ...], ...]:
        """Each finger's phases: the trial's own when it has them, else ``rule``'s (default
        ``PhaseRule()``) found in the finger's pdc. RawTrialError names the finger."""
        if self.phases is not None:
            return tuple(self.phases for _ in self.fingers)
        rule = rule or PhaseRule()
        out = []
        for i, finger in enumerate(self.fingers):
            try:
                out.append(rule.find(finger.pdc))
            except RawTrialError as err:
                raise err.located(finger=i) from None
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, as ``parse_trial`` reads it."""
        out: dict[str, Any] = {"fingers": [f.to_dict() for f in self.fingers]}
        if self.phases is not None:
            out["phases"] = [list(p) for p in self.phases]
        if self.timestamps is not None:
            out["timestamps"] = self.timestamps.tolist()
        return out

    def same_as(self, other: RawTrial) -> bool:
        """Equal signals, phases and timestamps (arrays compared exactly)."""
        if self.n_fingers != other.n_fingers or self.phases != other.phases:
            return False
        if (self.timestamps is None) != (other.timestamps is None) or (
            self.timestamps is not None and not np.array_equal(self.timestamps, other.timestamps)
        ):
            return False
        return all(
            np.array_equal(getattr(a, c), getattr(b, c))
            for a, b in zip(self.fingers, other.fingers, strict=True)
            for c in CHANNELS
        )


def _phases(value: Any, n_frames: int) -> tuple[tuple[int, int], ...]:
    def bad(why: str) -> RawTrialError:
        return RawTrialError(
            f"{why}; phases are [start, end) frame pairs in time order, "
            f"0 <= start < end <= {n_frames}",
            channel="phases",
        )

    try:
        arr = np.asarray(value)
    except ValueError:
        raise bad("not a list of pairs") from None
    if arr.dtype.kind not in "iuf" or arr.ndim != 2 or arr.shape[1] != 2 or len(arr) == 0:
        raise bad(f"expected a non-empty list of [start, end] pairs, got {arr.tolist()!r}"[:200])
    if arr.dtype.kind == "f" and not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
        raise bad("bounds must be whole frame numbers")
    pairs = tuple((int(s), int(e)) for s, e in arr.tolist())
    for k, (s, e) in enumerate(pairs):
        if not 0 <= s < e <= n_frames:
            raise bad(f"phase {k} is [{s}, {e})")
        if k and s < pairs[k - 1][1]:
            raise bad(f"phase {k} [{s}, {e}) starts before phase {k - 1} ends")
    return pairs


def parse_trial(
    data: Any, *, trial: int | None = None, rule: PhaseRule | None = None, check_phases: bool = True
) -> RawTrial:
    """A validated RawTrial from JSON-like data or arrays.

    ``data``: a RawTrial, or ``{"fingers": [{"pdc": [...], "tdc": [...], "tac": [...],
    "pac": [[22 values], ...], "electrodes": [[19 values], ...]}, ...], "phases": [[start,
    end], ...] (optional), "timestamps": [...] (optional)}``. ``trial`` is the index named
    in errors. With ``check_phases``, a trial without phases must have them findable in
    every finger by ``rule`` (default ``PhaseRule()``): a finger that never touches is an
    error here rather than when it is featurized.
    """
    try:
        if isinstance(data, RawTrial):
            parsed = data
        elif isinstance(data, Mapping):
            for key in data:
                if key not in _TRIAL_FIELDS:
                    raise RawTrialError(
                        f"unknown field {key!r}; a trial has {', '.join(_TRIAL_FIELDS)}"
                    )
            if "fingers" not in data:
                raise RawTrialError("missing field 'fingers'")
            parsed = RawTrial(
                fingers=data["fingers"],
                phases=data.get("phases"),
                timestamps=data.get("timestamps"),
            )
        else:
            raise RawTrialError(
                f"a trial must be an object with 'fingers', got {type(data).__name__}"
            )
        if check_phases:
            parsed.phase_bounds(rule)
    except RawTrialError as err:
        raise err.located(trial=trial) from None
    return parsed


def parse_trials(
    data: Sequence[Any], *, rule: PhaseRule | None = None, check_phases: bool = True
) -> list[RawTrial]:
    """``parse_trial`` for each item; errors name the item's index as the trial."""
    if isinstance(data, Mapping | str | bytes) or not isinstance(data, Sequence):
        raise RawTrialError(f"expected a list of trials, got {type(data).__name__}")
    return [
        parse_trial(d, trial=i, rule=rule, check_phases=check_phases) for i, d in enumerate(data)
    ]


# ------------------------------------------------------------------------------ phases
@dataclass(frozen=True)
class PhaseRule:
    """How the exploration phases of a finger are found in its ``pdc`` (DC pressure).

    1. The resting level is the median of the first ``rest_frames`` frames (a trial starts
       before the first contact).
    2. A frame is in contact while pdc exceeds the resting level by ``contact_counts``.
    3. A contact counts when its peak exceeds the resting level by ``peak_fraction`` of the
       finger's largest rise (and by ``contact_counts``), so a short twitch does not.
    4. Contacts separated by fewer than ``min_gap`` frames are one contact; contacts of
       fewer than ``min_frames`` frames are dropped.
    5. There must be exactly ``n_phases`` contacts: they are the phases, ``[start, end)``
       frame ranges in time order. Otherwise RawTrialError (channel 'pdc') says how many
       there were, or that the finger never touched.

    The defaults fit the pilot's recordings (tap, hold, squeeze; ~100 frames/s, rest noise
    under 1 count, contacts 100-500 counts above rest) and find its three phases in every
    finger of its 74 trials (tests/data/test_biotac_pilot.py).
    """

    n_phases: int = 3
    rest_frames: int = 100
    contact_counts: float = 10.0
    peak_fraction: float = 0.1
    min_gap: int = 20
    min_frames: int = 3

    def __post_init__(self) -> None:
        for name in ("n_phases", "rest_frames", "min_frames"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(
                    f"PhaseRule.{name} must be an integer >= 1, got {getattr(self, name)!r}"
                )
        if not isinstance(self.min_gap, int) or self.min_gap < 0:
            raise ValueError(f"PhaseRule.min_gap must be an integer >= 0, got {self.min_gap!r}")
        if not (math.isfinite(self.contact_counts) and self.contact_counts > 0):
            raise ValueError(f"PhaseRule.contact_counts must be > 0, got {self.contact_counts!r}")
        if not 0.0 <= self.peak_fraction < 1.0:
            raise ValueError(
                f"PhaseRule.peak_fraction must lie in [0, 1), got {self.peak_fraction!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def resting_level(self, pdc: np.ndarray) -> float:
        return float(np.median(np.asarray(pdc)[: self.rest_frames]))

    def find(self, pdc: np.ndarray) -> tuple[tuple[int, int], ...]:
        """The ``n_phases`` ``[start, end)`` frame ranges of one finger's pdc."""
        pdc = np.asarray(pdc, dtype=np.float64)
        if len(pdc) <= self.rest_frames:
            raise RawTrialError(
                f"the finger is too short to find phases in: {len(pdc)} frames, the resting "
                f"level alone takes the first {self.rest_frames}",
                channel="pdc",
            )
        rise = pdc - self.resting_level(pdc)
        peak = float(rise.max())
        if peak <= self.contact_counts:
            raise RawTrialError(
                f"no contact to find a phase in: pdc never rises more than "
                f"{self.contact_counts:g} counts above its resting level (its largest rise "
                f"is {peak:g})",
                channel="pdc",
            )
        starts, ends = _runs(rise > self.contact_counts)
        high = max(self.contact_counts, self.peak_fraction * peak)
        keep = [
            k for k, (s, e) in enumerate(zip(starts, ends, strict=True)) if rise[s:e].max() > high
        ]
        starts, ends = starts[keep], ends[keep]
        if len(starts) > 1:  # merge contacts split by short dips
            join = (starts[1:] - ends[:-1]) < self.min_gap
            starts = starts[np.r_[True, ~join]]
            ends = ends[np.r_[~join, True]]
        long = (ends - starts) >= self.min_frames
        starts, ends = starts[long], ends[long]
        if len(starts) != self.n_phases:
            found = ", ".join(f"[{s}, {e})" for s, e in zip(starts, ends, strict=True))
            raise RawTrialError(
                f"found {len(starts)} contact(s) ({found}) where {self.n_phases} exploration "
                f"phases are expected",
                channel="pdc",
            )
        return tuple((int(s), int(e)) for s, e in zip(starts, ends, strict=True))


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and (exclusive) ends of the runs of True in a 1-D boolean mask."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


# -------------------------------------------------------------------------------- HDF5
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
                    group.create_dataset("phases", data=np.asarray(trial.phases, dtype=np.int64))
                if trial.timestamps is not None:
                    group.create_dataset("timestamps", data=trial.timestamps)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


# ------------------------------------------------------------------------- the dataset
@dataclass(frozen=True, eq=False)
class BioTacDataset:
    """Raw trials of labelled objects, as read from a ``biotac:`` folder.

    trials: the RawTrials; labels: int64 (n,), index of each trial's object in
    ``class_names``; trial_ids: int64 (n,), distinct per trial (hold-out splits use them);
    groups: each trial's "<file name>/<group name>"; grip_pressure: float64 (n,), the set
    pressure parsed from group names ``…_pdc<P>_…`` (NaN where a name has none);
    attribute_values: float32 (K, M), graded values in [0, 1] and NaN (not known) allowed,
    M = 0 without an objects.csv.
    """

    trials: tuple[RawTrial, ...]
    labels: np.ndarray
    trial_ids: np.ndarray
    class_names: tuple[str, ...]
    attribute_names: tuple[str, ...] = ()
    attribute_values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    groups: tuple[str, ...] = ()
    grip_pressure: np.ndarray = field(default_factory=lambda: np.zeros(0))
    name: str = "biotac"

    def __post_init__(self) -> None:
        n, k = len(self.trials), len(self.class_names)
        object.__setattr__(self, "trials", tuple(self.trials))
        object.__setattr__(self, "labels", np.asarray(self.labels, dtype=np.int64))
        object.__setattr__(self, "trial_ids", np.asarray(self.trial_ids, dtype=np.int64))
        object.__setattr__(self, "class_names", tuple(self.class_names))
        object.__setattr__(self, "attribute_names", tuple(self.attribute_names))
        values = np.asarray(self.attribute_values, dtype=np.float32)
        if values.size == 0 and not self.attribute_names:
            values = np.zeros((k, 0), np.float32)
        object.__setattr__(self, "attribute_values", values)
        object.__setattr__(
            self, "groups", tuple(self.groups) or tuple(f"trial {i}" for i in range(n))
        )
        pressure = np.asarray(self.grip_pressure, dtype=np.float64)
        object.__setattr__(self, "grip_pressure", pressure if pressure.size else np.full(n, np.nan))
        if n == 0:
            raise DatasetError(f"dataset '{self.name}' has no trials")
        for name in ("labels", "trial_ids", "grip_pressure"):
            if getattr(self, name).shape != (n,):
                raise DatasetError(f"{name} must be ({n},), got {getattr(self, name).shape}")
        if len(self.groups) != n:
            raise DatasetError(f"groups must have {n} entries, got {len(self.groups)}")
        if len(np.unique(self.trial_ids)) != n:
            raise DatasetError("trial_ids must be distinct")
        if self.labels.min() < 0 or self.labels.max() >= k:
            raise DatasetError(f"labels must lie in [0, {k})")
        if values.shape != (k, len(self.attribute_names)):
            raise DatasetError(
                f"attribute_values must be ({k}, {len(self.attribute_names)}), got {values.shape}"
            )

    def __len__(self) -> int:
        return len(self.trials)

    def __repr__(self) -> str:
        return (
            f"BioTacDataset(name={self.name!r}, trials={len(self)}, "
            f"classes={len(self.class_names)}, attributes={len(self.attribute_names)})"
        )

    @property
    def n_classes(self) -> int:
        return len(self.class_names)

    def subset(self, index: Any) -> BioTacDataset:
        """The trials selected by a boolean mask or index array; classes unchanged."""
        idx = np.arange(len(self))[np.asarray(index)]
        return BioTacDataset(
            trials=tuple(self.trials[i] for i in idx),
            labels=self.labels[idx],
            trial_ids=self.trial_ids[idx],
            class_names=self.class_names,
            attribute_names=self.attribute_names,
            attribute_values=self.attribute_values,
            groups=tuple(self.groups[i] for i in idx),
            grip_pressure=self.grip_pressure[idx],
            name=self.name,
        )


def pressure_from_group(name: str) -> float:
    """The set grip pressure in a pilot group name ``<object>_pdc<P>_1cm_<NN>``; NaN if none."""
    match = _PRESSURE.search(name)
    return float(match.group(1)) if match else math.nan


def load_biotac(
    path: str | Path, rule: PhaseRule | None = None, check_phases: bool = True
) -> BioTacDataset:
    """A ``biotac:`` folder: one HDF5 file per object (the object's name is the file's stem),
    one group per trial, and optionally ``objects.csv`` (``name,<attribute>,...``).

    Objects and their trials come in name order; trial ids are 0 … n-1 in that order. With
    ``check_phases``, every finger of a trial without phases must show them to ``rule``
    (default ``PhaseRule()``). Errors name the file and the group (RawTrialError) or the
    objects.csv row and field (DatasetFileError).
    """
    from app.data.folder import read_objects_csv

    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"BioTac data folder not found: {root}")
    files = sorted(p for p in root.iterdir() if p.suffix.lower() in H5_SUFFIXES and p.is_file())
    if not files:
        raise DatasetFileError(
            root,
            f"no HDF5 file ({', '.join(H5_SUFFIXES)}) in the folder; "
            "a biotac folder holds one file per object",
        )
    names = [p.stem for p in files]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DatasetFileError(root, f"two files name object {repeated[0]!r}")
    trials, labels, groups, pressure = [], [], [], []
    for label, file in enumerate(files):
        for group, trial in read_biotac_h5(file).items():
            if check_phases:
                try:
                    trial.phase_bounds(rule)
                except RawTrialError as err:
                    raise err.located(file=str(file), group=group) from None
            trials.append(trial)
            labels.append(label)
            groups.append(f"{file.name}/{group}")
            pressure.append(pressure_from_group(group))
    attribute_names: tuple[str, ...] = ()
    values = np.zeros((len(names), 0), np.float32)
    if (root / OBJECTS_FILE).exists():
        table = read_objects_csv(root / OBJECTS_FILE)
        missing = [n for n in names if n not in table.names]
        if missing:
            raise DatasetFileError(
                root / OBJECTS_FILE,
                f"has no row for object {missing[0]!r} "
                f"(file {files[names.index(missing[0])].name})",
                field="name",
            )
        extra = [n for n in table.names if n not in names]
        if extra:
            row = table.names.index(extra[0]) + 2
            raise DatasetFileError(
                root / OBJECTS_FILE,
                f"object {extra[0]!r} has no file {extra[0]}.h5 in the folder",
                row=row,
                field="name",
            )
        attribute_names = table.attribute_names
        values = table.values[[table.names.index(n) for n in names]]
    return BioTacDataset(
        trials=tuple(trials),
        labels=np.array(labels),
        trial_ids=np.arange(len(trials)),
        class_names=tuple(names),
        attribute_names=attribute_names,
        attribute_values=values,
        groups=tuple(groups),
        grip_pressure=np.array(pressure),
        name="biotac",
    )


def write_biotac_folder(dataset: BioTacDataset, path: str | Path) -> None:
    """Write a dataset as a ``biotac:`` folder (one file per object; objects.csv when it has
    attributes). Group names are the part of ``groups`` after the file name."""
    from app.data.folder import write_objects_csv

    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    for k, name in enumerate(dataset.class_names):
        rows = np.flatnonzero(dataset.labels == k)
        if len(rows) == 0:
            raise DatasetError(f"object {name!r} has no trial; a biotac folder cannot hold it")
        trials = {dataset.groups[i].rpartition("/")[2]: dataset.trials[i] for i in rows}
        write_biotac_h5(root / f"{name}.h5", trials)
    if dataset.attribute_names:
        write_objects_csv(
            root / OBJECTS_FILE,
            dataset.class_names,
            dataset.attribute_names,
            dataset.attribute_values,
        )


__all__ = [
    "CHANNELS",
    "BioTacDataset",
    "FingerSignals",
    "PhaseRule",
    "RawTrial",
    "RawTrialError",
    "load_biotac",
    "parse_trial",
    "parse_trials",
    "pressure_from_group",
    "read_biotac_h5",
    "write_biotac_folder",
    "write_biotac_h5",
]
