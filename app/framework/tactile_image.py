"""The paper's tactile image (Sect. V-A) from raw BioTac trials, as a fitted featurizer.

For each finger of a trial and each exploration phase, eight readings are resampled to
``n_steps`` (30) time samples: the 4 pressure and temperature signals ``pdc``, ``pac``,
``tac``, ``tdc`` and the first ``n_components`` (4) principal components of the 19
electrodes. The image has ``(4 + n_components) × n_phases`` rows (24 for the pilot's tap,
hold and squeeze; 32 for PHAC-2's four procedures) and ``n_steps`` columns, rows in phase
order and, within a phase, in the order pdc, pac, tac, tdc, e0 … e3 (as the simulator's).

- Phases: the trial's own ``[start, end)`` frame ranges when it has them, else found in
  each finger's pdc by a ``PhaseRule`` (app/data/biotac_phases.py).
- Resampling: a phase of frames ``[s, e)`` spans the time ``[s - 0.5, e - 0.5)`` (frame k
  at time k, owning the unit interval around it); it is cut into ``n_steps`` bins of width
  ``w = (e - s) / n_steps`` and each sample is the mean of the signal, linearly
  interpolated between frames, over one bin width centred at ``s - 0.5 + (i + offset) w``
  (clipped to the recording). That is an anti-aliasing box filter when a phase is longer
  than ``n_steps`` frames and linear interpolation when it is shorter. ``offset`` 0.5 (bin
  centres) gives the image of a trial; ``n_offsets`` evenly spaced offsets in (0, 1)
  give the paper's sub-sampling augmentation of training data.
- pac: the 22 sub-samples of frame k, flattened in time order, sit at times
  ``k - 0.5 + (j + 0.5) / 22``; they are resampled like every other signal, so a pac
  sample is the mean AC pressure over its bin.
- Electrodes: a PCA fitted on the resampled electrode signals of the training trials'
  fingers gives the components; a finger's resampled electrodes are projected on them.
- ``baseline="rest"`` first subtracts, per finger, each channel's resting level (median
  of the frames before the first phase, at most ``rest_frames`` of them): the BioTacs'
  resting pressure, temperature and impedances differ between sensors and trials.
- ``normalize``: each image row is centred and scaled by its mean and standard deviation
  over the training images (all time samples).

PCA and normalisation are fitted on training trials only; the fitted state is plain
arrays and JSON scalars (``get_state`` / ``from_state``), as a model bundle stores them.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Self

import numpy as np
from scipy.interpolate import make_interp_spline

from app.data.biotac import (
    N_ELECTRODES,
    PAC_SUBSAMPLES,
    BioTacDataset,
    FingerSignals,
    PhaseRule,
    RawTrial,
    RawTrialError,
    parse_trial,
)
from app.data.dataset import TactileDataset
from app.framework.errors import FrameworkError, NotFittedError

STATE_KIND = "tactile-image"
STATE_VERSION = 1
BASELINES = ("none", "rest")
SIGNALS = ("pdc", "pac", "tac", "tdc")
# frame-rate columns resampled together: pdc, tac, tdc, then the 19 electrodes
_FRAME_COLUMNS = 3 + N_ELECTRODES


def resample(
    values: np.ndarray,
    times: np.ndarray,
    start: float,
    end: float,
    n_steps: int,
    offset: float = 0.5,
) -> np.ndarray:
    """Bin means of a sampled signal over ``[start, end)`` (see the module docstring).

    values: (n,) or (n, k) samples at strictly increasing ``times`` (n >= 2); the signal
    between samples is their linear interpolation. Returns (n_steps,) or (n_steps, k):
    sample i is the mean over ``[c_i - w/2, c_i + w/2]`` clipped to the sampled span, with
    ``w = (end - start) / n_steps`` and ``c_i = start + (i + offset) w``.
    """
    if not end > start:
        raise ValueError(f"resample needs end > start, got [{start}, {end})")
    width = (end - start) / n_steps
    centres = start + (np.arange(n_steps) + offset) * width
    lo = np.clip(centres - width / 2, times[0], times[-1])
    hi = np.clip(centres + width / 2, times[0], times[-1])
    # only the samples the bins reach: a phase is a small part of a long recording
    first = max(int(np.searchsorted(times, lo[0], side="right")) - 1, 0)
    last = min(int(np.searchsorted(times, hi[-1], side="left")) + 1, len(times))
    t, v = times[first:last], values[first:last]
    if len(t) < 2:
        t, v = times[max(first - 1, 0) : first + 2], values[max(first - 1, 0) : first + 2]
    line = make_interp_spline(t, v, k=1)
    area = line.antiderivative()
    span = hi - lo
    flat = span <= 1e-9 * max(width, 1.0)
    safe = np.where(flat, 1.0, span)
    means = (area(hi) - area(lo)) / (safe if v.ndim == 1 else safe[:, None])
    if flat.any():
        means[flat] = line(lo[flat])
    return means


class TactileImageFeaturizer:
    """Raw BioTac trials -> one tactile image per finger, ``(8 × n_phases, n_steps)``.

    Parameters
    ----------
    n_steps : time samples per phase (the paper's 30).
    n_components : electrode principal components kept (the paper's 4; at most 19).
    phase_names : names of the exploration phases, in time order; their number is the
        number of phases (the pilot's three contacts by default).
    phase_rule : how phases are found in a finger's pdc when a trial does not give them;
        default ``PhaseRule(n_phases=len(phase_names))``.
    baseline : "rest" (default) subtracts each finger's resting level per channel; "none"
        keeps the raw counts. On the pilot, "rest" carried objects across grip pressures
        better (docs/DATASETS.md).
    n_offsets : sub-sampling offsets of ``augment`` (the paper's 5).
    normalize : centre and scale each image row by its training mean and std.
    """

    def __init__(
        self,
        n_steps: int = 30,
        n_components: int = 4,
        phase_names: Sequence[str] = ("tap", "hold", "squeeze"),
        phase_rule: PhaseRule | None = None,
        baseline: str = "rest",
        n_offsets: int = 5,
        normalize: bool = True,
    ) -> None:
        self.n_steps = n_steps
        self.n_components = n_components
        self.phase_names = tuple(phase_names)
        self.phase_rule = phase_rule
        self.baseline = baseline
        self.n_offsets = n_offsets
        self.normalize = normalize
        self._check_params()
        self.pca_mean_: np.ndarray | None = None
        self.pca_components_: np.ndarray | None = None
        self.image_mean_: np.ndarray | None = None
        self.image_scale_: np.ndarray | None = None

    # ----------------------------------------------------------------- parameters
    def _check_params(self) -> None:
        def positive_int(name: str, upper: int | None = None) -> None:
            v = getattr(self, name)
            if (
                isinstance(v, bool)
                or not isinstance(v, int | np.integer)
                or v < 1
                or (upper is not None and v > upper)
            ):
                bound = f" and <= {upper}" if upper is not None else ""
                raise ValueError(f"{name} must be an integer >= 1{bound}, got {v!r}")

        positive_int("n_steps")
        positive_int("n_components", N_ELECTRODES)
        positive_int("n_offsets")
        if not self.phase_names or any(not isinstance(p, str) or not p for p in self.phase_names):
            raise ValueError(f"phase_names must be non-empty names, got {self.phase_names!r}")
        if len(set(self.phase_names)) != len(self.phase_names):
            raise ValueError(f"phase_names must be distinct, got {self.phase_names!r}")
        if self.phase_rule is None:
            self.phase_rule = PhaseRule(n_phases=len(self.phase_names))
        elif not isinstance(self.phase_rule, PhaseRule):
            raise ValueError(
                f"phase_rule must be a PhaseRule, got {type(self.phase_rule).__name__}"
            )
        if self.phase_rule.n_phases != len(self.phase_names):
            raise ValueError(
                f"phase_rule finds {self.phase_rule.n_phases} phases but "
                f"phase_names names {len(self.phase_names)}"
            )
        if self.baseline not in BASELINES:
            raise ValueError(
                f"baseline must be one of {', '.join(BASELINES)}, got {self.baseline!r}"
            )
        if not isinstance(self.normalize, bool):
            raise ValueError(f"normalize must be true or false, got {self.normalize!r}")

    @property
    def readings(self) -> tuple[str, ...]:
        return SIGNALS + tuple(f"e{i}" for i in range(self.n_components))

    @property
    def channel_names(self) -> tuple[str, ...]:
        """ "<phase>/<reading>" of each image row."""
        return tuple(f"{p}/{r}" for p in self.phase_names for r in self.readings)

    @property
    def image_shape(self) -> tuple[int, int]:
        return (len(self.phase_names) * len(self.readings), self.n_steps)

    @property
    def offsets(self) -> np.ndarray:
        """The augmentation offsets: ``(j + 0.5) / n_offsets``, j = 0 … n_offsets - 1."""
        return (np.arange(self.n_offsets) + 0.5) / self.n_offsets

    @property
    def is_fitted(self) -> bool:
        return self.image_mean_ is not None

    # -------------------------------------------------------------------- fitting
    def fit(self, trials: Sequence[RawTrial | Any]) -> Self:
        """Fit the electrode PCA and the row normalisation on training trials (RawTrials or
        their JSON form); RawTrialError names a trial that cannot be featurized."""
        self._check_params()
        parsed = self._parse(trials)
        if not parsed:
            raise ValueError("fit needs at least one trial")
        for i, trial in enumerate(parsed):
            if trial.phases is not None and None in trial.phases:
                missing = [
                    n for n, p in zip(self.phase_names, trial.phases, strict=False) if p is None
                ]
                raise RawTrialError(
                    f"lacks phase(s) {', '.join(missing)}; a featurizer learns from whole trials",
                    trial=i,
                    channel="phases",
                )
        blocks = np.concatenate([self._blocks(t, i, 0.5) for i, t in enumerate(parsed)])
        electrodes = blocks[:, :, len(SIGNALS) :, :]  # (fingers, phases, 19, steps)
        rows = electrodes.transpose(0, 1, 3, 2).reshape(-1, N_ELECTRODES).astype(np.float64)
        if len(rows) < self.n_components:
            raise ValueError(f"fit needs at least {self.n_components} electrode samples")
        from sklearn.decomposition import PCA  # fitting only: loading a model stays light

        pca = PCA(n_components=self.n_components, svd_solver="full").fit(rows)
        self.pca_mean_ = pca.mean_.astype(np.float64)
        self.pca_components_ = pca.components_.astype(np.float64)
        images = self._images(blocks)
        if self.normalize:
            self.image_mean_ = images.mean(axis=(0, 2))
            std = images.std(axis=(0, 2))
            self.image_scale_ = np.where(std > 1e-12, std, 1.0)
        else:
            c = self.image_shape[0]
            self.image_mean_, self.image_scale_ = np.zeros(c), np.ones(c)
        return self

    def _parse(self, trials: Sequence[RawTrial | Any]) -> list[RawTrial]:
        if isinstance(trials, RawTrial):
            trials = [trials]
        return [parse_trial(t, trial=i, check_phases=False) for i, t in enumerate(trials)]

    # ---------------------------------------------------------------- transforming
    def transform(
        self, trials: RawTrial | Sequence[RawTrial | Any], offset: float = 0.5
    ) -> np.ndarray:
        """float32 images ``(total fingers, rows, n_steps)``: each trial's fingers in order,
        trials in order. A single RawTrial gives its fingers' images, ``(fingers, rows,
        n_steps)``, which a recognizer answers together (one answer per trial)."""
        self._require_fitted()
        if not 0.0 <= offset <= 1.0:
            raise ValueError(f"offset must lie in [0, 1], got {offset!r}")
        parsed = self._parse(trials)
        if not parsed:
            return np.zeros((0, *self.image_shape), np.float32)
        blocks = np.concatenate([self._blocks(t, i, offset) for i, t in enumerate(parsed)])
        return self._images(blocks).astype(np.float32)

    def fit_transform(self, trials: Sequence[RawTrial | Any]) -> np.ndarray:
        return self.fit(trials).transform(trials)

    def augment(
        self, trials: Sequence[RawTrial | Any], trial_ids: Iterable[int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """The augmented training images: every finger of every trial at each of the
        ``n_offsets`` sub-sampling offsets (the paper's 2 fingers × 5 = 10 per trial).
        Returns float32 images (n_images, rows, n_steps) and the int64 trial id of each."""
        self._require_fitted()
        parsed = self._parse(trials)
        ids = np.asarray(list(trial_ids), dtype=np.int64)
        if ids.shape != (len(parsed),):
            raise ValueError(
                f"augment needs one trial id per trial: {len(parsed)} trials, {ids.shape} ids"
            )
        images, owners = [], []
        for i, trial in enumerate(parsed):
            for offset in self.offsets:
                images.append(self._images(self._blocks(trial, i, float(offset))))
                owners.append(np.full(trial.n_fingers, ids[i]))
        if not images:
            return np.zeros((0, *self.image_shape), np.float32), np.zeros(0, np.int64)
        return np.concatenate(images).astype(np.float32), np.concatenate(owners)

    def phases(
        self, trial: RawTrial, index: int | None = None
    ) -> tuple[tuple[tuple[int, int], ...], ...]:
        """Each finger's phase bounds as this featurizer uses them; RawTrialError if a
        trial gives, or a finger shows, another number of phases."""
        try:
            bounds = trial.phase_bounds(self.phase_rule)
        except RawTrialError as err:
            raise err.located(trial=index) from None
        if trial.phases is not None and len(trial.phases) != len(self.phase_names):
            raise RawTrialError(
                f"the trial gives {len(trial.phases)} phase(s) where the featurizer uses "
                f"{len(self.phase_names)} ({', '.join(self.phase_names)})",
                trial=index,
                channel="phases",
            )
        return bounds

    def _blocks(self, trial: RawTrial, index: int, offset: float) -> np.ndarray:
        """(fingers, phases, 4 + 19, n_steps): the resampled signals and electrodes."""
        out = np.empty(
            (trial.n_fingers, len(self.phase_names), len(SIGNALS) + N_ELECTRODES, self.n_steps)
        )
        for f, (finger, bounds) in enumerate(
            zip(trial.fingers, self.phases(trial, index), strict=True)
        ):
            try:
                out[f] = self._finger_block(finger, bounds, offset)
            except RawTrialError as err:
                raise err.located(trial=index, finger=f) from None
        return out

    def _finger_block(
        self, finger: FingerSignals, bounds: tuple[tuple[int, int] | None, ...], offset: float
    ) -> np.ndarray:
        """(phases, 4 + 19, n_steps); a phase not done (None) is NaN throughout, the block
        a model that answers from some procedures reads as missing."""
        n = finger.n_frames
        frames = np.column_stack([finger.pdc, finger.tac, finger.tdc, finger.electrodes]).astype(
            np.float64
        )
        frame_times = np.arange(n, dtype=np.float64)
        pac = finger.pac.astype(np.float64).ravel()
        pac_times = (
            frame_times[:, None] - 0.5 + (np.arange(PAC_SUBSAMPLES) + 0.5) / PAC_SUBSAMPLES
        ).ravel()
        block = np.full((len(bounds), len(SIGNALS) + N_ELECTRODES, self.n_steps), np.nan)
        for p, bound in enumerate(bounds):
            if bound is None:
                continue
            s, e = bound
            lo, hi = s - 0.5, e - 0.5
            f = resample(frames, frame_times, lo, hi, self.n_steps, offset)  # (steps, 22)
            block[p, 0] = f[:, 0]  # pdc
            block[p, 1] = resample(pac, pac_times, lo, hi, self.n_steps, offset)
            block[p, 2] = f[:, 1]  # tac
            block[p, 3] = f[:, 2]  # tdc
            block[p, len(SIGNALS) :] = f[:, 3:].T
        if self.baseline == "rest":
            first = next(b for b in bounds if b is not None)
            rest = min(self.phase_rule.rest_frames, first[0])
            if rest < 1:
                raise RawTrialError(
                    "baseline 'rest' needs frames at rest before the first "
                    "phase; this finger's first phase starts at frame 0",
                    channel="pdc",
                )
            level = np.median(frames[:rest], axis=0)
            level_pac = np.median(finger.pac[:rest])
            block[:, 0] -= level[0]
            block[:, 1] -= level_pac
            block[:, 2] -= level[1]
            block[:, 3] -= level[2]
            block[:, len(SIGNALS) :] -= level[3:, None]
        return block

    def _images(self, blocks: np.ndarray) -> np.ndarray:
        """Blocks (fingers, phases, 4 + 19, steps) -> images (fingers, rows, steps)."""
        signals = blocks[:, :, : len(SIGNALS), :]
        electrodes = blocks[:, :, len(SIGNALS) :, :]
        pcs = np.einsum("fpes,ce->fpcs", electrodes - self.pca_mean_[:, None], self.pca_components_)
        images = np.concatenate([signals, pcs], axis=2).reshape(len(blocks), -1, self.n_steps)
        if self.image_mean_ is not None:
            images = (images - self.image_mean_[:, None]) / self.image_scale_[:, None]
        return images

    def _require_fitted(self) -> None:
        if not self.is_fitted:
            raise NotFittedError("TactileImageFeaturizer is not fitted; call fit() first")

    # ------------------------------------------------------------------ its state
    def get_params(self) -> dict[str, Any]:
        """The constructor's parameters as JSON-able values."""
        return {
            "n_steps": int(self.n_steps),
            "n_components": int(self.n_components),
            "phase_names": list(self.phase_names),
            "phase_rule": self.phase_rule.to_dict(),
            "baseline": self.baseline,
            "n_offsets": int(self.n_offsets),
            "normalize": self.normalize,
        }

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """(JSON-able metadata, named float64 arrays): what a model bundle stores."""
        self._require_fitted()
        meta = {
            "kind": STATE_KIND,
            "version": STATE_VERSION,
            **self.get_params(),
            "channel_names": list(self.channel_names),
        }
        arrays = {
            "pca_mean": self.pca_mean_,
            "pca_components": self.pca_components_,
            "image_mean": self.image_mean_,
            "image_scale": self.image_scale_,
        }
        return meta, {k: np.asarray(v, dtype=np.float64).copy() for k, v in arrays.items()}

    @classmethod
    def from_state(cls, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        """The fitted featurizer ``get_state`` described; ValueError says what is wrong."""
        if meta.get("kind") != STATE_KIND or meta.get("version") != STATE_VERSION:
            raise ValueError(
                f"not a tactile-image featurizer state of version {STATE_VERSION}: "
                f"kind {meta.get('kind')!r}, version {meta.get('version')!r}"
            )
        try:
            params = {
                k: meta[k]
                for k in (
                    "n_steps",
                    "n_components",
                    "phase_names",
                    "baseline",
                    "n_offsets",
                    "normalize",
                )
            }
            params["phase_rule"] = PhaseRule(**meta["phase_rule"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"featurizer state lacks or garbles a parameter: {exc}") from None
        new = cls(**params)
        rows = new.image_shape[0]
        shapes = {
            "pca_mean": (N_ELECTRODES,),
            "pca_components": (new.n_components, N_ELECTRODES),
            "image_mean": (rows,),
            "image_scale": (rows,),
        }
        for name, shape in shapes.items():
            if name not in arrays:
                raise ValueError(f"featurizer state lacks array {name!r}")
            a = np.asarray(arrays[name], dtype=np.float64)
            if a.shape != shape or not np.isfinite(a).all():
                raise ValueError(
                    f"featurizer array {name!r} must be finite of shape {shape}, got {a.shape}"
                )
            setattr(new, f"{name}_", a.copy())
        if (new.image_scale_ <= 0).any():
            raise ValueError("featurizer array 'image_scale' must be positive")
        return new


#: the options ``featurizer_from_params`` takes: the constructor's parameters
PARAMS = (
    "n_steps",
    "n_components",
    "phase_names",
    "phase_rule",
    "baseline",
    "n_offsets",
    "normalize",
)


def featurizer_from_params(params: dict[str, Any] | None) -> TactileImageFeaturizer:
    """An unfitted featurizer from a recognizer's ``featurizer_params`` hyper-parameter: a
    JSON-able dict of constructor options (``get_params()``'s form: ``phase_rule`` as the
    dict of a ``PhaseRule``), any of them left out taking its default; None: all defaults.
    A bad option raises FrameworkError naming it."""
    if params is None:
        return TactileImageFeaturizer()
    if not isinstance(params, dict):
        raise FrameworkError(
            f"featurizer_params must be None or a dict of the featurizer's options "
            f"({', '.join(PARAMS)}), got {type(params).__name__}"
        )
    unknown = sorted(set(params) - set(PARAMS))
    if unknown:
        raise FrameworkError(
            f"featurizer_params has unknown option(s) {', '.join(map(repr, unknown))}; "
            f"the featurizer's options are {', '.join(PARAMS)}"
        )
    options = dict(params)
    rule = options.get("phase_rule")
    try:
        if isinstance(rule, dict):
            options["phase_rule"] = PhaseRule(**rule)
        return TactileImageFeaturizer(**options)
    except (TypeError, ValueError) as exc:
        raise FrameworkError(f"featurizer_params: {exc}") from None


def featurize_dataset(
    raw: BioTacDataset, featurizer: TactileImageFeaturizer, augment: bool = False
) -> TactileDataset:
    """A TactileDataset of tactile images from raw trials and a fitted featurizer: one
    sample per finger (per offset with ``augment``), each keeping its trial's id and
    label. Fit the featurizer on training trials only (``raw.subset``) before evaluating."""
    if augment:
        images, ids = featurizer.augment(raw.trials, raw.trial_ids)
    else:
        images = featurizer.transform(raw.trials)
        ids = np.repeat(raw.trial_ids, [t.n_fingers for t in raw.trials])
    label_of = dict(zip(raw.trial_ids.tolist(), raw.labels.tolist(), strict=True))
    return TactileDataset(
        samples=images,
        labels=np.array([label_of[i] for i in ids.tolist()], dtype=np.int64),
        trials=ids,
        class_attributes=raw.attribute_values,
        attribute_names=raw.attribute_names,
        class_names=raw.class_names,
        name=raw.name,
        procedures=featurizer.phase_names,  # the image's rows come in phase blocks
    )
