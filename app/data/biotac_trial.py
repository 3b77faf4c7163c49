"""The raw BioTac trial: ``FingerSignals`` (one finger's five channels) and ``RawTrial``
(its fingers, phases and timestamps), validated on construction, and ``parse_trial`` /
``parse_trials`` for their JSON form. The channels and their shapes are listed in
``app.data.biotac``'s docstring."""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.data.biotac_errors import RawTrialError
from app.data.biotac_phases import PhaseRule

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


def _numbers(value: Any, channel: str, dtype: type = np.float32) -> np.ndarray:
    """``value`` as a ``dtype`` array; RawTrialError unless it is numeric and rectangular."""
    try:
        raw = np.asarray(value)
    except ValueError:  # ragged nested lists
        raise RawTrialError("rows have different lengths", channel=channel) from None
    if raw.dtype == object:  # None (JSON null) or text among numbers
        raise RawTrialError("values must all be numbers (null or text among them)", channel=channel)
    if raw.dtype.kind not in "iuf":
        raise RawTrialError(f"values must be numbers, got {raw.dtype.name} values", channel=channel)
    with np.errstate(over="ignore"):
        return np.asarray(raw, dtype=dtype)


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
        by the fingers; None: found from each finger's pdc by a ``PhaseRule``. A phase the
        robot did not do is None in that list (``[[10, 40], None, [60, 90]]``: no hold),
        and a model that answers from some procedures answers from the others.
    timestamps: (T,) time of each frame, kept as given (not used by the features).
    """

    fingers: tuple[FingerSignals, ...]
    phases: tuple[tuple[int, int] | None, ...] | None = None
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
            # float64 from the values as given: float32 keeps steps of 128 s at Unix times
            ts = _numbers(self.timestamps, "timestamps", np.float64)
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
            out["phases"] = [None if p is None else list(p) for p in self.phases]
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


def _phases(value: Any, n_frames: int) -> tuple[tuple[int, int] | None, ...]:
    def bad(why: str) -> RawTrialError:
        return RawTrialError(
            f"{why}; phases are [start, end) frame pairs in time order, "
            f"0 <= start < end <= {n_frames}, or null for a phase not done",
            channel="phases",
        )

    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise bad(f"expected a list of [start, end] pairs, got {type(value).__name__}")
    entries = list(value)
    if not entries:
        raise bad("expected a non-empty list of [start, end] pairs, got []")
    pairs: list[tuple[int, int] | None] = []
    for k, entry in enumerate(entries):
        if entry is None:
            pairs.append(None)
            continue
        try:
            arr = np.asarray(entry)
        except ValueError:
            raise bad(f"phase {k} is not a [start, end] pair") from None
        if arr.dtype.kind not in "iuf" or arr.shape != (2,):
            raise bad(f"phase {k} is not a [start, end] pair: {entry!r}"[:200])
        if arr.dtype.kind == "f" and not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
            raise bad(f"phase {k}: bounds must be whole frame numbers")
        pairs.append((int(arr[0]), int(arr[1])))
    done = [(k, p) for k, p in enumerate(pairs) if p is not None]
    if not done:
        raise bad("every phase is null; a trial needs at least one phase done")
    for i, (k, (s, e)) in enumerate(done):
        if not 0 <= s < e <= n_frames:
            raise bad(f"phase {k} is [{s}, {e})")
        if i and s < done[i - 1][1][1]:
            raise bad(f"phase {k} [{s}, {e}) starts before phase {done[i - 1][0]} ends")
    return tuple(pairs)


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
