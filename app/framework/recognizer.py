"""The interface every recognition method implements (Fig. 1 as a contract).

A recognizer is fitted on known classes, routes each sample to the known-class
classifier (FC_Y) or the novel-class classifier (FC_Z) by a novelty score, and
grows by zero-shot enrollment (``add_novel_classes``) and one-shot samples
(``add_one_shot``). Both return a *new* recognizer; the original is untouched,
so a service can keep serving it while the new one is built.

Novelty scores are oriented so that higher means more novel; for the paper's
GMM the score is the negated weighted log-likelihood and the threshold is
-sigma_nov.

Two kinds of input. A recognizer fitted on a ``TactileDataset`` takes fixed-shape samples
(``input_kind == "samples"``). One fitted on raw BioTac trials (a ``BioTacDataset``) fits
a ``TactileImageFeaturizer`` on its training trials and keeps it (``featurizer``, stored in
its model bundle); it takes raw trials (``input_kind == "raw_trials"``): ``trial_samples``
turns trials into its samples, one tactile image per finger, and ``recognize_trials``
answers once per trial from all of its fingers (``recognize_batch`` with ``groups``).
Giving one kind to a model of the other raises ``InputKindError``.

Attributes are optional: a model fitted on classes without attributes (M = 0) recognises
its known classes and novel classes enrolled from real samples
(``add_novel_classes_from_samples``, where the method supports it), and refuses zero-shot
enrolment (``ZeroShotUnavailableError``).
"""

from __future__ import annotations

import copy
import difflib
import inspect
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple, Self

import numpy as np

from app.data.biotac import BioTacDataset, RawTrial, RawTrialError, parse_trial
from app.data.dataset import TactileDataset
from app.data.procedures import ProcedureError, present
from app.framework.errors import (
    AttributeVectorError,
    DuplicateClassError,
    FrameworkError,
    InputKindError,
    InputShapeError,
    MissingProcedureError,
    NonFiniteInputError,
    NotFittedError,
    TrialInputError,
    UnknownClassError,
    UnsupportedOperationError,
    ZeroShotUnavailableError,
)
from app.framework.params import Constraint
from app.framework.runtime import ensure_threads_configured

#: ``input_kind`` of a model fitted on fixed-shape samples / on raw BioTac trials
SAMPLES = "samples"
RAW_TRIALS = "raw_trials"
#: how ``recognize_batch`` fuses the samples of a group (see ``fuse_groups``)
FUSION_RULE = "mean"
#: ``next_procedure`` says stop (None) once the answer's probability reaches the target
#: confidence, this by default, and at least ``MIN_PROCEDURES`` procedures were done.
#: Chosen on PHAC-2's development splits (seeds 1-2, 10 splits,
#: ``bench/research/explore_stopping.py``): at 0.4 the rule used 0.42 of the robot time,
#: known-object accuracy -0.005 and ``gzsl_h`` +0.008 from all procedures; at 0.3, 0.36 of
#: the time with the same accuracy; at 0.5, 0.54.
TARGET_CONFIDENCE = 0.4
#: One procedure alone answers confidently and wrongly too often: on the same splits,
#: stopping at the first confident answer lost 0.017-0.023 of known-object accuracy at any
#: target from 0.3 to 0.5; a second procedure before stopping lost 0.003-0.005.
MIN_PROCEDURES = 2


class ClassScore(NamedTuple):
    class_name: str
    probability: float


class Recognition(NamedTuple):
    """The answer for one sample."""

    class_name: str
    kind: str  # "known" | "novel"
    is_novel: bool
    novelty_score: float
    top_k: tuple[ClassScore, ...]
    procedures_used: tuple[str, ...] = ()
    next_procedure: str | None = None  # the procedure to do next; None: stop


@dataclass(frozen=True)
class RecognitionBatch:
    """The answers for a batch as arrays: what the service serialises (building 4 Python
    objects per sample first cost about as much as the forward pass). ``answers()`` gives
    the same as ``Recognition`` objects; ``batch[a:b]`` is a batch of rows a … b-1.

    Classes are indexed into ``class_names`` (known classes, then novel ones); a sample
    answered from fewer classes than ``top_k`` has its ranking padded with index -1.
    """

    class_names: tuple[str, ...]
    n_known: int
    top_index: np.ndarray  # (N, k) int64, best first
    top_probability: np.ndarray  # (N, k) float64
    is_novel: np.ndarray  # (N,) bool: novelty score above the threshold
    novelty_score: np.ndarray  # (N,) float64
    #: the model's procedures, and which each answer used ((N, P) bool) and which it asks
    #: for next ((N,) index into ``procedures``, -1: none); P = 0 for a model without them
    procedures: tuple[str, ...] = ()
    procedures_used: np.ndarray | None = None
    next_procedure: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.novelty_score)

    def __getitem__(self, rows: slice) -> RecognitionBatch:
        return RecognitionBatch(
            self.class_names,
            self.n_known,
            self.top_index[rows],
            self.top_probability[rows],
            self.is_novel[rows],
            self.novelty_score[rows],
            self.procedures,
            None if self.procedures_used is None else self.procedures_used[rows],
            None if self.next_procedure is None else self.next_procedure[rows],
        )

    def procedure_fields(self) -> list[tuple[list[str], str | None]]:
        """(``procedures_used``, ``next_procedure``) of each answer, by name."""
        names = self.procedures
        if self.procedures_used is None or self.next_procedure is None:
            return [(list(names), None)] * len(self)
        return [
            ([names[j] for j in np.flatnonzero(used)], names[nxt] if nxt >= 0 else None)
            for used, nxt in zip(self.procedures_used, self.next_procedure.tolist(), strict=True)
        ]

    @property
    def class_kinds(self) -> list[str]:
        """``"known"`` or ``"novel"`` for each of ``class_names``."""
        return ["known"] * self.n_known + ["novel"] * (len(self.class_names) - self.n_known)

    @property
    def is_novel_class(self) -> np.ndarray:
        """(N,) bool: the answer is a novel class (FC_Z), not a known one (FC_Y)."""
        return self.top_index[:, 0] >= self.n_known

    def records(self, class_ids: Mapping[str, int | None] | None = None) -> list[dict[str, Any]]:
        """The answers as JSON-ready dicts, in the shape of ``POST /v1/recognize``'s results;
        with ``class_ids`` (class name → the store's id) every class named carries its
        ``class_id`` too. Built straight from the arrays: building pydantic models first cost
        more than the forward pass of a sample."""
        names = self.class_names
        label = (
            [{"class_name": n} for n in names]
            if class_ids is None
            else [{"class_id": class_ids.get(n), "class_name": n} for n in names]
        )
        return self.labelled_records(label, self.class_kinds)

    def labelled_records(
        self, label: Sequence[Mapping[str, Any]], kinds: Sequence[str]
    ) -> list[dict[str, Any]]:
        """``records`` from each class's label dict and kind, which a caller answering many
        batches of one model (the service) builds once."""
        return [
            {
                **label[idx[0]],
                "kind": kinds[idx[0]],
                "is_novel": novel,
                "novelty_score": score,
                "top_k": [
                    {**label[j], "probability": q}
                    for j, q in zip(idx, top_p, strict=True)
                    if j >= 0
                ],
                "procedures_used": used,
                "next_procedure": nxt,
            }
            for idx, top_p, novel, score, (used, nxt) in zip(
                self.top_index.tolist(),
                self.top_probability.tolist(),
                self.is_novel.tolist(),
                self.novelty_score.tolist(),
                self.procedure_fields(),
                strict=True,
            )
        ]

    def answers(self) -> list[Recognition]:
        names, kinds = self.class_names, self.class_kinds
        return [
            Recognition(
                names[idx[0]],
                kinds[idx[0]],
                nov,
                score,
                tuple(ClassScore(names[j], q) for j, q in zip(idx, tp, strict=True) if j >= 0),
                tuple(used),
                nxt,
            )
            for idx, tp, nov, score, (used, nxt) in zip(
                self.top_index.tolist(),
                self.top_probability.tolist(),
                self.is_novel.tolist(),
                self.novelty_score.tolist(),
                self.procedure_fields(),
                strict=True,
            )
        ]


@dataclass
class NoveltyTuning:
    """How the novelty threshold was chosen (Sect. VI-B, Fig. 7)."""

    thresholds: np.ndarray
    known_kept: np.ndarray  # accuracy of calling held-out known samples known, per threshold
    val_novel: np.ndarray  # accuracy of calling validation-novel samples novel, per threshold
    threshold: float
    known_kept_at_threshold: float
    val_novel_at_threshold: float
    auroc: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "thresholds": self.thresholds.tolist(),
            "known_kept": self.known_kept.tolist(),
            "val_novel": self.val_novel.tolist(),
            "threshold": self.threshold,
            "known_kept_at_threshold": self.known_kept_at_threshold,
            "val_novel_at_threshold": self.val_novel_at_threshold,
            "auroc": self.auroc,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NoveltyTuning:
        return cls(
            thresholds=np.asarray(d["thresholds"], dtype=np.float64),
            known_kept=np.asarray(d["known_kept"], dtype=np.float64),
            val_novel=np.asarray(d["val_novel"], dtype=np.float64),
            threshold=float(d["threshold"]),
            known_kept_at_threshold=float(d["known_kept_at_threshold"]),
            val_novel_at_threshold=float(d["val_novel_at_threshold"]),
            auroc=float(d.get("auroc", float("nan"))),
        )


@dataclass
class ClassRegistry:
    """Known and novel classes with their attribute vectors, and novel classes' real samples."""

    attribute_names: tuple[str, ...] = ()
    known_names: list[str] = field(default_factory=list)
    known_attributes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    novel_names: list[str] = field(default_factory=list)
    novel_attributes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    # real samples that arrived for novel classes (one-shot learning), by class name
    novel_samples: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def all_names(self) -> list[str]:
        return self.known_names + self.novel_names

    def kind_of(self, name: str) -> str:
        if name in self.known_names:
            return "known"
        if name in self.novel_names:
            return "novel"
        raise UnknownClassError(f"unknown class '{name}'")


class TactileRecognizer(ABC):
    """Base class of recognition methods; see the module docstring.

    Hyper-parameters follow scikit-learn's conventions (``app.framework.params``): a
    subclass's constructor takes every hyper-parameter as a named argument and only
    stores it under the same name; ``get_params`` and ``set_params`` work from that
    signature (a model bundle stores ``get_params()`` and loading sets them back), and
    ``fit`` checks the values against the class's ``_parameter_constraints`` first.
    """

    method: ClassVar[str] = "abstract"
    #: True when enrolments never change what ``fit`` trained (the known part), so novel
    #: classes can be dropped and rebuilt from the registry alone: then a withdrawal needs
    #: no full retrain. False where one-shot samples fine-tune shared parts (``paper``).
    novel_part_separable: ClassVar[bool] = False
    #: True where a novel class can be recognised from its real samples alone, with no
    #: attribute (``add_novel_classes_from_samples``, on a model fitted without attributes)
    learns_classes_from_samples: ClassVar[bool] = False
    #: True where attribute values may be graded (in [0, 1]: "somewhat soft" is 0.5) or not
    #: known (NaN), in the training classes' vectors and in zero-shot enrolments; False where
    #: the method learns 0/1 attributes only
    graded_attributes: ClassVar[bool] = False
    #: True where the parts that learn attributes can be fitted again alone, on the same
    #: training samples (``with_attributes``): a grown vocabulary or a class's new values
    #: then need no full retrain
    attributes_separable: ClassVar[bool] = False
    #: True where known classes can be added, or given more samples, without a refit
    #: (``with_known_samples``): a promotion then needs no full retrain
    learns_known_incrementally: ClassVar[bool] = False
    #: the method's own defaults for featurizer options its ``featurizer_params`` leaves
    #: out (the featurizer's defaults for the rest); documented with that parameter
    _featurizer_defaults: ClassVar[dict[str, Any]] = {}
    #: parameter name -> what its value must satisfy; checked by ``fit``. A subclass
    #: extends its parent's: ``{**Parent._parameter_constraints, ...}``.
    _parameter_constraints: ClassVar[dict[str, Constraint]] = {}

    def __init__(self) -> None:
        # the state of an unfitted recognizer (not hyper-parameters): fit and bundle loading set it
        self.input_shape: tuple[int, ...] | None = None
        self.registry = ClassRegistry()
        self.novelty_threshold: float = float("inf")
        self.novelty_tuning: NoveltyTuning | None = None
        self.metrics: dict[str, Any] = {}
        # the featurizer fitted on raw training trials; None for a model of fixed-shape samples
        self.featurizer_: Any = None
        # the exploratory procedures a sample holds (``TactileDataset.procedures``); () none
        self.procedures: tuple[str, ...] = ()

    # --------------------------------------------------------- hyper-parameters
    @classmethod
    def _get_param_names(cls) -> list[str]:
        """The constructor's parameter names, in its signature's order (scikit-learn's
        ``BaseEstimator._get_param_names``, which sorts them)."""
        init = cls.__init__
        if init is TactileRecognizer.__init__:
            return []
        names = []
        for p in inspect.signature(init).parameters.values():
            if p.name == "self":
                continue
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(
                    f"{cls.__name__}.__init__ must name every hyper-parameter "
                    f"(no *args or **kwargs), as scikit-learn requires"
                )
            names.append(p.name)
        return names

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The hyper-parameters, by name, as the constructor takes them (``deep`` is
        scikit-learn's; a recognizer has no nested estimators)."""
        return {name: getattr(self, name) for name in self._get_param_names()}

    def set_params(self, **params: Any) -> Self:
        """Set hyper-parameters by name; they are checked by the next ``fit``."""
        valid = self._get_param_names()
        for name, value in params.items():
            if name not in valid:
                raise FrameworkError(
                    f"invalid parameter {name!r} for {type(self).__name__}; "
                    f"its parameters are: {', '.join(valid)}"
                )
            setattr(self, name, value)
        return self

    def _validate_params(self) -> None:
        """Check every hyper-parameter against ``_parameter_constraints``; a subclass adds
        the checks that involve several parameters. Raises FrameworkError."""
        for name, constraint in self._parameter_constraints.items():
            constraint.check(name, getattr(self, name))
        if "featurizer_params" in self._get_param_names():
            self._new_featurizer()  # a bad option is refused before any work

    def _new_featurizer(self) -> Any:
        """An unfitted ``TactileImageFeaturizer`` with the ``featurizer_params``
        hyper-parameter's options; an option left out takes the method's default
        (``_featurizer_defaults``), else the featurizer's."""
        from app.framework.tactile_image import featurizer_from_params

        params = getattr(self, "featurizer_params", None)
        if isinstance(params, dict) or params is None:
            params = {**self._featurizer_defaults, **(params or {})}
        return featurizer_from_params(params)

    # ----------------------------------------------------------------- fitting
    def fit(self, dataset: TactileDataset | BioTacDataset, progress: bool = False) -> Self:
        """Train on ``dataset``; every class in it becomes a known class.

        ``dataset`` is a ``TactileDataset`` of fixed-shape samples, or a ``BioTacDataset``
        of raw trials: then a ``TactileImageFeaturizer`` (options: the method's
        ``featurizer_params``) is fitted on its trials, every finger of every trial becomes a
        training image at each of the featurizer's sub-sampling offsets (its ``n_offsets``:
        1 takes each finger once), and the model keeps the featurizer. Pass the training
        trials only: an evaluation splits its trials first.

        The classes need 0/1 attributes (``class_attributes``), or values in [0, 1] and NaN
        (not known) where the method has ``graded_attributes``, or none at all (M = 0): a
        model without attributes recognises its known classes, and novel classes only from
        their samples.
        """
        self._validate_params()
        featurizer = None
        if isinstance(dataset, BioTacDataset):
            from app.framework.tactile_image import featurize_dataset

            featurizer = self._new_featurizer().fit(dataset.trials)
            dataset = featurize_dataset(dataset, featurizer, augment=True)
        elif not isinstance(dataset, TactileDataset):
            raise FrameworkError(
                "fit takes a TactileDataset (fixed-shape samples) or a BioTacDataset (raw "
                f"trials), got {type(dataset).__name__}"
            )
        if len(dataset) == 0:
            raise NotFittedError("cannot fit on an empty dataset")
        ensure_threads_configured()  # the default thread limits, where no entry point chose them
        attributes = self._training_attributes(dataset)
        self.input_shape = dataset.input_shape
        self.featurizer_ = featurizer
        self.procedures = dataset.procedures
        self.registry = ClassRegistry(
            attribute_names=dataset.attribute_names,
            known_names=list(dataset.class_names),
            known_attributes=attributes,
            novel_names=[],
            novel_attributes=np.zeros((0, dataset.n_attributes), np.float32),
        )
        self._fit(dataset, progress)
        return self

    def _training_attributes(self, dataset: TactileDataset) -> np.ndarray:
        """(K, M) the training classes' vectors as this method learns them. No attribute at
        all is allowed (known classes only); graded or not-known values stop here, as
        reading ``class_attributes`` says, unless the method has ``graded_attributes``."""
        if not dataset.n_attributes:
            return np.zeros((dataset.n_classes, 0), np.float32)
        if self.graded_attributes:
            return dataset.attribute_values.copy()
        return dataset.class_attributes.copy()

    def with_attributes(
        self,
        dataset: TactileDataset | BioTacDataset,
        novel_attributes: Mapping[str, np.ndarray] | None = None,
    ) -> Self:
        """A new recognizer that describes classes by ``dataset``'s attributes: its
        vocabulary and its classes' values. ``dataset`` holds the same known classes and
        training samples (or raw trials) as ``fit`` was given, and may differ only in its
        attributes. Only the parts that learn attributes are fitted again (methods with
        ``attributes_separable``); the novel classes are dropped, and those named in
        ``novel_attributes`` (class name -> vector in the new vocabulary) are added back by
        ``add_novel_classes`` (their one-shot samples go back with ``add_one_shot``).

        Elsewhere UnsupportedOperationError says to fit the method again."""
        self._require_fitted()
        if not self.attributes_separable:
            raise UnsupportedOperationError(
                f"method '{self.method}' learns attributes with the rest of the model; fit it "
                "again on the new attributes instead"
            )
        if isinstance(dataset, BioTacDataset):
            from app.framework.tactile_image import featurize_dataset

            # the featurizer fit made, on the same trials: the same training images
            dataset = featurize_dataset(dataset, self.featurizer_, augment=True)
        if list(dataset.class_names) != list(self.registry.known_names):
            raise FrameworkError(
                "with_attributes takes the known classes the model was fitted on, in their "
                f"order; got {len(dataset.class_names)} classes for "
                f"{len(self.registry.known_names)}"
            )
        new = self.without_novel_classes()
        new.registry.attribute_names = dataset.attribute_names
        new.registry.known_attributes = new._training_attributes(dataset)
        new.registry.novel_attributes = np.zeros((0, dataset.n_attributes), np.float32)
        new._refit_attributes(dataset)
        if novel_attributes:
            new = new.add_novel_classes(list(novel_attributes), list(novel_attributes.values()))
        return new

    def _refit_attributes(self, dataset: TactileDataset) -> None:
        """Fit the parts that learn attributes again; methods with ``attributes_separable``
        override it."""
        raise UnsupportedOperationError(f"method '{self.method}' cannot refit its attributes")

    # ------------------------------------------------------------ input kinds
    @property
    def featurizer(self) -> Any:
        """The ``TactileImageFeaturizer`` fitted on the raw training trials, which turns
        raw trials into this model's samples; None for a model of fixed-shape samples."""
        return self.featurizer_

    @property
    def input_kind(self) -> str:
        """``"raw_trials"`` for a model fitted on raw BioTac trials (it recognises trials:
        ``recognize_trials``), ``"samples"`` for one fitted on fixed-shape samples."""
        return RAW_TRIALS if self.featurizer_ is not None else SAMPLES

    @property
    def has_attributes(self) -> bool:
        """The model describes classes by at least one attribute (zero-shot is possible)."""
        return len(self.registry.attribute_names) > 0

    def _takes_samples(self) -> str:
        shape = ", ".join(map(str, self.input_shape))
        return f"this model takes fixed-shape samples of shape (N, {shape})"

    def _takes_trials(self) -> str:
        shape = ", ".join(map(str, self.input_shape))
        return (
            "this model was fitted on raw BioTac trials and takes raw trials "
            "(recognize_trials, attribute_proba_trials; trial_samples turns trials into its "
            f"samples, the tactile images of shape (N, {shape}), one per finger)"
        )

    def trial_samples(self, trials: Any) -> tuple[np.ndarray, np.ndarray]:
        """The model's samples of raw trials: one tactile image per finger of each trial,
        made by the fitted featurizer. ``trials``: a ``RawTrial``, its JSON form
        (``{"fingers": [...], "phases": ... optional}``, see ``app.data.biotac.parse_trial``)
        or a list of them.

        Returns ``(images, trial_index)``: float32 ``(F, *input_shape)`` images, every
        trial's fingers in order, and the int64 ``(F,)`` index of each image's trial in
        ``trials`` (the ``groups`` of ``recognize_batch``). ``trial_samples([t])[0]`` are
        the samples of one trial, as ``add_one_shot`` takes them.

        Raises InputKindError on a model of fixed-shape samples, TrialInputError (naming
        trial, finger and channel) for a malformed trial or one whose phases cannot be
        found, InputShapeError for an empty list.
        """
        self._require_fitted()
        if self.featurizer_ is None:
            raise InputKindError(
                f"{self._takes_samples()}, not raw BioTac trials: it was not fitted on raw "
                "trials, so it has no featurizer to make samples of them"
            )
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
            images = self.featurizer_.transform(parsed)
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

    def recognize_trials(self, trials: Any, top_k: int = 3) -> RecognitionBatch:
        """One answer per raw trial, from the images of all its fingers together (the
        ``groups`` fusion of ``recognize_batch``). Errors as ``trial_samples``."""
        images, index = self.trial_samples(trials)
        return self.recognize_batch(images, top_k, groups=index)

    def attribute_proba_trials(self, trials: Any) -> np.ndarray:
        """(n_trials, M): ``attribute_proba`` of each trial, the mean over its fingers."""
        images, index = self.trial_samples(trials)
        return group_mean(self.attribute_proba(images), index, int(index[-1]) + 1)

    @abstractmethod
    def _fit(self, dataset: TactileDataset, progress: bool) -> None:
        """Train the known-class classifier and the novelty detector (threshold tuned)."""

    # --------------------------------------------------------------- inference
    @abstractmethod
    def _known_proba(self, samples: np.ndarray) -> np.ndarray:
        """(N, K) probabilities over the known classes."""

    @abstractmethod
    def _novel_proba(self, samples: np.ndarray) -> np.ndarray:
        """(N, L) probabilities over the novel classes (L >= 1)."""

    @abstractmethod
    def _novelty_score(self, samples: np.ndarray) -> np.ndarray:
        """(N,) novelty scores, higher = more novel."""

    def _all_scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Novelty scores, known and novel probabilities in one pass; override to share work."""
        novel_p = self._novel_proba(x) if self.registry.novel_names else None
        return self._novelty_score(x), self._known_proba(x), novel_p

    def known_proba(self, samples: np.ndarray) -> np.ndarray:
        x, used = self._checked(samples)
        if used is None:
            return self._known_proba(x)
        return self._by_procedures(x, used, lambda x, keep: self._scores_from(x, keep)[1])

    def novel_proba(self, samples: np.ndarray) -> np.ndarray:
        if not self.registry.novel_names:
            raise UnknownClassError("the model has no novel classes yet")
        x, used = self._checked(samples)
        if used is None:
            return self._novel_proba(x)
        return self._by_procedures(x, used, lambda x, keep: self._scores_from(x, keep)[2])

    def novelty_score(self, samples: np.ndarray) -> np.ndarray:
        x, used = self._checked(samples)
        if used is None:
            return self._novelty_score(x)
        return self._by_procedures(x, used, lambda x, keep: self._scores_from(x, keep)[0])

    def is_novel(self, samples: np.ndarray) -> np.ndarray:
        return self.novelty_score(samples) > self.novelty_threshold

    def attribute_proba(self, samples: np.ndarray) -> np.ndarray:
        """(N, M) probability that each attribute describes each sample's object, in the
        registry's attribute order: what a touch feels like, to help describe an object
        nobody registered yet. Only methods that predict attributes from a sample have it."""
        x, used = self._checked(samples)
        if used is None:
            return self._attribute_proba(x)
        every = len(self.procedures)
        return self._by_procedures(
            x,
            used,
            lambda x, keep: (
                self._attribute_proba(x)
                if len(keep) == every
                else self._subset_attribute_proba(x, keep)
            ),
        )

    # ------------------------------------------------------- missing procedures
    @property
    def answers_from_some_procedures(self) -> bool:
        """True where samples lacking some procedures are answered (from those they hold);
        elsewhere such a sample is a MissingProcedureError."""
        return False

    @property
    def first_procedure(self) -> str | None:
        """The procedure to do first, before any answer: the one the model recognises its
        known classes best from alone; None for a model that needs every procedure."""
        return None

    def _checked(self, samples: Any) -> tuple[np.ndarray, np.ndarray | None]:
        """The validated samples, and which procedures each holds ((N, P) bool) where some
        lack one (None when every sample is complete)."""
        x = self.validate_samples(samples, partial=True)
        if not self.procedures or not np.isnan(x).any():
            return x, None
        return x, present(x, self.procedures)

    def _scores_from(
        self, x: np.ndarray, keep: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(novelty scores, known, novel probabilities) from the procedures ``keep``."""
        if len(keep) == len(self.procedures):
            return self._all_scores(x)
        return self._subset_scores(x, keep)

    def _subset_scores(
        self, x: np.ndarray, keep: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``_all_scores`` from the procedures ``keep`` (indices) alone; methods with
        ``answers_from_some_procedures`` override it."""
        raise UnsupportedOperationError(f"method '{self.method}' answers from every procedure")

    def _subset_attribute_proba(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """``_attribute_proba`` from the procedures ``keep`` alone."""
        raise UnsupportedOperationError(f"method '{self.method}' answers from every procedure")

    def _next_procedures(
        self, known_p: np.ndarray, used: np.ndarray, ask: np.ndarray
    ) -> np.ndarray:
        """(N,) index of the procedure each row of ``ask`` should do next (-1 elsewhere),
        from its known-class probabilities and the procedures it used ((N, P) bool)."""
        return np.full(len(known_p), -1, np.int64)

    @staticmethod
    def _by_procedures(
        x: np.ndarray, used: np.ndarray, part: Callable[[np.ndarray, np.ndarray], Any]
    ) -> Any:
        """``part(rows, keep)`` on each group of rows that hold the same procedures ``keep``
        (indices), put back in row order. ``part`` returns an array or a tuple of arrays
        (a None entry stays None)."""
        patterns, which = np.unique(used, axis=0, return_inverse=True)
        which = which.ravel()
        out: list[np.ndarray | None] = []
        single = False
        for g, pattern in enumerate(patterns):
            rows = np.flatnonzero(which == g)
            got = part(x[rows], np.flatnonzero(pattern))
            single = not isinstance(got, tuple)
            parts = (got,) if single else got
            if not out:
                out = [
                    None if a is None else np.empty((len(x), *a.shape[1:]), a.dtype) for a in parts
                ]
            for o, a in zip(out, parts, strict=True):
                if o is not None:
                    o[rows] = a
        return out[0] if single else tuple(out)

    def _attribute_proba(self, samples: np.ndarray) -> np.ndarray:
        raise UnsupportedOperationError(
            f"method '{self.method}' does not predict attributes from a sample (method 'best' does)"
        )

    def recognize(
        self,
        samples: np.ndarray,
        top_k: int = 3,
        groups: np.ndarray | None = None,
        target_confidence: float = TARGET_CONFIDENCE,
    ) -> list[Recognition]:
        """Fig. 1: ND(x) routes each sample (or each group, see ``recognize_batch``) to
        FC_Y or FC_Z."""
        return self.recognize_batch(samples, top_k, groups, target_confidence).answers()

    def recognize_batch(
        self,
        samples: np.ndarray,
        top_k: int = 3,
        groups: np.ndarray | None = None,
        target_confidence: float = TARGET_CONFIDENCE,
    ) -> RecognitionBatch:
        """``recognize`` as arrays (the service's hot path): one row per sample.

        With ``groups`` ((N,) integers 0 … G-1, every one used), the samples of a group are
        evidence about one object (the fingers of one trial, several touches of one thing)
        and the batch has G rows, one answer per group: its known-class probabilities,
        novel-class probabilities and novelty score are the means over its samples
        (``fuse_groups``), and the fused score is routed by the same threshold. A group of
        one sample gets exactly that sample's answer.

        A sample may lack procedures (NaN throughout their blocks) where the model
        ``answers_from_some_procedures``; each answer names the procedures it used and the
        one to do next: None once its top probability reaches ``target_confidence`` or no
        procedure is left (``next_procedure``), and never before ``MIN_PROCEDURES`` were done
        where the model has that many.
        """
        if not 0.0 < float(target_confidence) <= 1.0:
            raise FrameworkError(f"target_confidence must lie in (0, 1], got {target_confidence}")
        x, used = self._checked(samples)
        if used is None:
            scores, known_p, novel_p = self._all_scores(x)
        else:
            scores, known_p, novel_p = self._by_procedures(x, used, self._scores_from)
        if groups is not None:
            g = check_groups(groups, len(x))
            scores, known_p, novel_p = fuse_groups(g, scores, known_p, novel_p)
            if used is not None:
                used = group_mean(used.astype(np.float64), g, int(g.max()) + 1) > 0
        batch = self._batch(scores, known_p, novel_p, top_k)
        if used is None:
            return self._complete(batch)
        unsure = batch.top_probability[:, 0] < float(target_confidence)
        ask = (unsure | (used.sum(axis=1) < MIN_PROCEDURES)) & ~used.all(axis=1)
        batch.__dict__.update(
            procedures=self.procedures,
            procedures_used=used,
            next_procedure=self._next_procedures(known_p, used, ask),
        )
        return batch

    def _complete(self, batch: RecognitionBatch) -> RecognitionBatch:
        """``batch``, answers from complete samples: every procedure used, none next (a
        model that names no procedures leaves the fields empty)."""
        if self.procedures:
            every = np.ones((1, len(self.procedures)), bool)
            batch.__dict__.update(
                procedures=self.procedures,
                procedures_used=np.broadcast_to(every, (len(batch), len(self.procedures))),
                next_procedure=np.full(len(batch), -1, np.int64),
            )
        return batch

    def _batch(
        self,
        scores: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
        top_k: int,
    ) -> RecognitionBatch:
        """The answers from the scores: route each row by its novelty score, rank the top
        k of the classifier that answers it. One row takes ``_one_row``: the same bits,
        without the machinery for many rows (about half the cost for one sample)."""
        if len(scores) == 1:
            return self._one_row(scores, known_p, novel_p, top_k)
        return self._rows(scores, known_p, novel_p, top_k)

    def _one_row(
        self,
        scores: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
        top_k: int,
    ) -> RecognitionBatch:
        """``_rows`` for a batch of one row, bit for bit: the same comparison routes it and
        the same ``ranked`` orders its row."""
        novel = scores > self.novelty_threshold
        reg = self.registry
        known_names = reg.known_names
        k = top_k if top_k > 1 else 1
        if novel_p is not None and novel[0]:
            row, offset = novel_p[0], len(known_names)
        else:
            row, offset = known_p[0], 0
        order = ranked(row[None], k)[0]
        value = row[order]
        if offset:
            order = order + offset
        missing = k - len(order)
        if missing > 0:
            order = np.concatenate([order, np.full(missing, -1, np.int64)])
            value = np.concatenate([value, np.full(missing, np.nan)])
        batch = object.__new__(RecognitionBatch)
        # the frozen dataclass's fields, set without its __init__'s object.__setattr__ calls
        batch.__dict__.update(
            class_names=(*known_names, *reg.novel_names),
            n_known=len(known_names),
            top_index=order[None],
            top_probability=value[None],
            is_novel=novel,
            novelty_score=scores.astype(np.float64),
            procedures=(),
            procedures_used=None,
            next_procedure=None,
        )
        return batch

    def _rows(
        self,
        scores: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
        top_k: int,
    ) -> RecognitionBatch:
        """``_batch`` for any number of rows (the reference ``_one_row`` must match)."""
        novel = scores > self.novelty_threshold
        reg = self.registry
        n, k, n_known = len(scores), max(1, top_k), len(reg.known_names)
        # Route, then rank top-k for each classifier's rows at once.
        # Without novel classes a novel sample can only be answered from the known ones.
        use_novel = novel & (novel_p is not None)
        n_novel = int(np.count_nonzero(use_novel))
        if n_novel in (0, n):
            # one classifier answers every row (always so for one sample): no masked copies
            probs, offset = (known_p, 0) if n_novel == 0 else (novel_p, n_known)
            top_index, top_p = _top_k(probs, k, offset)
        else:
            top_index = np.full((n, k), -1, np.int64)
            top_p = np.full((n, k), np.nan)
            for probs, offset, rows in ((known_p, 0, ~use_novel), (novel_p, n_known, use_novel)):
                top_index[rows], top_p[rows] = _top_k(probs[rows], k, offset)
        return RecognitionBatch(
            tuple(reg.all_names), n_known, top_index, top_p, novel, scores.astype(np.float64)
        )

    # --------------------------------------------------------------- enrolment
    def add_novel_classes(
        self,
        names: Sequence[str],
        attribute_vectors: np.ndarray | Sequence[Sequence[float]],
        *,
        allow_known_vectors: bool = False,
        **options: Any,
    ) -> Self:
        """Zero-shot enrolment: a new recognizer that also recognises these classes.

        A novel class whose attribute vector equals an existing class's is refused:
        FC_Z could never tell them apart from attributes. ``allow_known_vectors``
        relaxes that for *known* classes only, as the paper's evaluation splits do
        (routing by novelty detection still separates them); novel classes must
        always differ from each other.

        A model fitted without attributes (M = 0) has nothing to recognise a described
        class by: ZeroShotUnavailableError (enrol such a class with
        ``add_novel_classes_from_samples``).
        """
        self._require_fitted()
        if not self.has_attributes:
            raise ZeroShotUnavailableError(
                "this model was fitted on classes without attributes: a class without "
                "attributes cannot be recognised zero-shot; add samples "
                "(add_novel_classes_from_samples)"
            )
        names = [str(n) for n in names]
        vectors = self.validate_attribute_vectors(attribute_vectors)
        if len(names) != len(vectors):
            raise AttributeVectorError(f"{len(names)} names but {len(vectors)} attribute vectors")
        reg = self.registry
        existing = set(reg.all_names)
        all_vectors = (
            reg.novel_attributes
            if allow_known_vectors
            else np.concatenate([reg.known_attributes, reg.novel_attributes])
        )
        existing_names = reg.novel_names if allow_known_vectors else reg.all_names
        for i, name in enumerate(names):
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in existing or names.count(name) > 1:
                raise DuplicateClassError(f"class '{name}' already exists")
            same = np.flatnonzero(same_vectors(all_vectors, vectors[i]))
            if len(same):
                other = existing_names[same[0]]
                raise DuplicateClassError(
                    f"class '{name}' has the same attribute vector as existing class '{other}'"
                )
            same_new = [names[j] for j in range(i) if same_vectors(vectors[j][None], vectors[i])[0]]
            if same_new:
                raise DuplicateClassError(
                    f"classes '{same_new[0]}' and '{name}' have the same attribute vector"
                )
        new = copy.deepcopy(self)
        new.registry.novel_names = reg.novel_names + names
        new.registry.novel_attributes = np.concatenate([reg.novel_attributes, vectors]).astype(
            np.float32
        )
        new._refit_novel(**options)
        return new

    def add_novel_classes_from_samples(
        self, samples: Mapping[str, np.ndarray], **options: Any
    ) -> Self:
        """Novel classes without a description, learnt from their real samples alone: a new
        recognizer that also recognises them. ``samples``: class name -> its samples (at
        least one; for a raw-trial model, e.g. ``trial_samples([trial])[0]``). Later samples
        come with ``add_one_shot`` as for any novel class.

        Only methods that can recognise a class from its samples alone (``best``) take
        them: on a model without attributes (M = 0), or one with ``graded_attributes``, where
        such a class's vector is not known for every attribute. Elsewhere a novel class is
        described by attributes (``add_novel_classes``) and UnsupportedOperationError says so.
        """
        self._require_fitted()
        if self.has_attributes and not self.graded_attributes:
            raise UnsupportedOperationError(
                "this model describes classes by attributes: enrol a class with its attributes "
                "(add_novel_classes), then add its samples (add_one_shot)"
            )
        if not self.learns_classes_from_samples:
            raise UnsupportedOperationError(
                f"method '{self.method}' cannot recognise a class from its samples alone "
                "(without attributes); method 'best' can"
            )
        if not isinstance(samples, Mapping) or not samples:
            raise FrameworkError("give at least one class: a mapping of class name -> samples")
        reg = self.registry
        checked: dict[str, np.ndarray] = {}
        for name, x in samples.items():
            name = str(name)
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in reg.all_names or name in checked:
                raise DuplicateClassError(f"class '{name}' already exists")
            checked[name] = self.validate_samples(x)
        new = copy.deepcopy(self)
        new.registry.novel_names = reg.novel_names + list(checked)
        unknown = np.full((len(checked), len(reg.attribute_names)), np.nan, np.float32)
        new.registry.novel_attributes = np.concatenate([reg.novel_attributes, unknown])
        new.registry.novel_samples.update(checked)
        new._refit_novel(**options)
        return new

    def add_one_shot(self, class_name: str, samples: np.ndarray, **options: Any) -> Self:
        """One-shot learning: real samples of a novel class refine FC_Z (Sect. IV-F).
        For a raw-trial model the samples are tactile images, ``trial_samples([trial])[0]``
        for one trial (both fingers)."""
        self._require_fitted()
        kind = self.registry.kind_of(class_name)
        if kind != "novel":
            raise UnknownClassError(
                f"class '{class_name}' is a known class; one-shot samples are for novel classes"
            )
        x = self.validate_samples(samples)
        new = copy.deepcopy(self)
        prev = new.registry.novel_samples.get(class_name)
        new.registry.novel_samples[class_name] = x if prev is None else np.concatenate([prev, x])
        new._refit_novel(**options)
        return new

    def with_known_samples(
        self,
        samples: Mapping[str, np.ndarray],
        attribute_vectors: Mapping[str, Any] | None = None,
    ) -> Self:
        """Known classes learnt without a refit: a new recognizer in which every class named
        in ``samples`` (name -> its samples, as for ``add_one_shot``) is known and has learnt
        those samples. A known class gains them; a novel class is promoted (with the
        attribute vector it was enrolled with); a new name becomes a known class, described
        by ``attribute_vectors[name]`` (not known, NaN, where the method takes graded
        attributes and none is given). The other novel classes stay. Only for methods with
        ``learns_known_incrementally``; the result differs from a model fitted on everything
        by what the method's ``_grow_known`` documents."""
        self._require_fitted()
        if not self.learns_known_incrementally:
            raise UnsupportedOperationError(
                f"method '{self.method}' cannot learn known classes without a refit; fit it "
                "again instead"
            )
        if not isinstance(samples, Mapping) or not samples:
            raise FrameworkError("give at least one class: a mapping of class name -> samples")
        vectors = dict(attribute_vectors or {})
        reg = self.registry
        new = copy.deepcopy(self)
        nreg = new.registry
        known = list(reg.known_names)
        added: list[np.ndarray] = []
        grown: list[tuple[int, np.ndarray]] = []  # (known class index, its samples)
        for name, x in samples.items():
            name = str(name)
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in vectors and name in reg.known_names:
                raise FrameworkError(f"class '{name}' is known already: it keeps its attributes")
            if name in reg.novel_names:
                i = nreg.novel_names.index(name)
                vector = nreg.novel_attributes[i]
                nreg.novel_names = nreg.novel_names[:i] + nreg.novel_names[i + 1 :]
                nreg.novel_attributes = np.delete(nreg.novel_attributes, i, axis=0)
                nreg.novel_samples.pop(name, None)
            elif name not in reg.known_names:
                if name in vectors:
                    vector = self.validate_attribute_vectors([vectors[name]])[0]
                elif self.graded_attributes or not self.has_attributes:
                    vector = np.full(len(reg.attribute_names), np.nan, np.float32)
                else:
                    raise AttributeVectorError(f"new known class '{name}' needs its attributes")
            if name not in known:
                known.append(name)
                added.append(np.asarray(vector, np.float32)[None])
            grown.append((known.index(name), self.validate_samples(x)))
        nreg.known_names = known
        if added:
            nreg.known_attributes = np.concatenate([reg.known_attributes, *added]).astype(
                np.float32
            )
        new._grow_known(
            np.concatenate([x for _, x in grown]),
            np.concatenate([np.full(len(x), c, np.int64) for c, x in grown]),
        )
        new._refit_novel()
        return new

    def _grow_known(self, samples: np.ndarray, labels: np.ndarray) -> None:
        """Learn ``samples`` of known classes ``labels`` (indices into the registry's known
        classes, which already lists any new ones); ``learns_known_incrementally`` methods
        override it."""
        raise UnsupportedOperationError(f"method '{self.method}' cannot grow its known part")

    def without_novel_classes(self) -> Self:
        """A new recognizer with the known part only: no novel class, no one-shot sample.
        Only for methods with ``novel_part_separable``; others must be fitted again."""
        self._require_fitted()
        if not self.novel_part_separable:
            raise UnsupportedOperationError(
                f"method '{self.method}' adapts shared parts to enrolments; fit it again instead"
            )
        new = copy.deepcopy(self)
        reg = new.registry
        reg.novel_names, reg.novel_samples = [], {}
        reg.novel_attributes = np.zeros((0, len(reg.attribute_names)), np.float32)
        new._reset_novel()
        return new

    def _reset_novel(self) -> None:
        """Forget FC_Z; methods with ``novel_part_separable`` override it."""
        raise UnsupportedOperationError(f"method '{self.method}' cannot drop its novel classes")

    @abstractmethod
    def _refit_novel(self, **options: Any) -> None:
        """Rebuild FC_Z from the registry's novel classes and their real samples."""

    # -------------------------------------------------------------- validation
    def validate_samples(self, samples: np.ndarray, partial: bool = False) -> np.ndarray:
        """float32 array of shape (N, *input_shape); a single sample gets a batch axis.

        Raw trials given as samples, and samples of another shape given to a model fitted
        on raw trials, raise InputKindError saying which input the model takes. With
        ``partial``, a sample may lack whole procedures (NaN throughout their blocks) where
        the model ``answers_from_some_procedures``; else MissingProcedureError says so."""
        self._require_fitted()
        # an array is never trials (the isinstance checks against Mapping cost more)
        if not isinstance(samples, np.ndarray) and _looks_like_trials(samples):
            raise InputKindError(
                f"{self._takes_samples() if self.featurizer_ is None else self._takes_trials()}"
                "; got raw trials where samples were expected"
                + (" (use recognize_trials)" if self.featurizer_ is not None else "")
            )
        try:
            x = np.asarray(samples, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise InputShapeError(f"samples are not a numeric array: {exc}") from None
        if x.shape == self.input_shape:
            x = x[None]
        if x.ndim != len(self.input_shape) + 1 or x.shape[1:] != self.input_shape:
            if self.featurizer_ is not None:
                raise InputKindError(f"{self._takes_trials()}; got samples of shape {x.shape}")
            raise InputShapeError(
                f"expected samples of shape (N, {', '.join(map(str, self.input_shape))}), "
                f"got {x.shape}"
            )
        if len(x) == 0:
            raise InputShapeError("expected at least one sample, got an empty batch")
        if not np.isfinite(x).all():
            self._check_missing(x, partial)
        return x

    def _check_missing(self, x: np.ndarray, partial: bool) -> None:
        """The error for samples with NaN or infinity, unless every NaN is a whole missing
        procedure that ``partial`` allows and the model answers without."""
        flat = x.reshape(len(x), -1)
        infinite = np.isinf(flat).any(axis=1)
        if infinite.any() or not self.procedures:
            bad = int(infinite.argmax()) if infinite.any() else int(np.isnan(flat).any(1).argmax())
            raise NonFiniteInputError(
                f"sample {bad} contains {'infinity' if infinite.any() else 'NaN'}"
            )
        try:
            used = present(x, self.procedures)
        except ProcedureError as exc:
            raise MissingProcedureError(str(exc)) from None
        if not partial or not self.answers_from_some_procedures:
            i = int((~used.all(axis=1)).argmax())
            lacking = [p for p, u in zip(self.procedures, used[i], strict=True) if not u]
            why = (
                f"method '{self.method}' answers from every procedure"
                if partial
                else "samples learnt by the model need every procedure"
            )
            raise MissingProcedureError(f"sample {i} lacks {', '.join(lacking)}: {why}")

    def validate_attribute_vectors(self, vectors: Any) -> np.ndarray:
        m = len(self.registry.attribute_names)
        try:
            v = np.asarray(vectors, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise AttributeVectorError(f"attribute vectors are not numeric: {exc}") from None
        if v.ndim == 1:
            v = v[None]
        if v.ndim != 2 or v.shape[1] != m:
            raise AttributeVectorError(
                f"expected attribute vectors of length {m}, got shape {v.shape}"
            )
        if self.graded_attributes:
            known = ~np.isnan(v)
            if not ((v[known] >= 0) & (v[known] <= 1)).all():
                raise AttributeVectorError(
                    "attribute values must lie in [0, 1] (NaN: not known), got "
                    f"{float(v[known][(v[known] < 0) | (v[known] > 1)][0])}"
                )
        elif not np.isin(v, (0.0, 1.0)).all():
            raise AttributeVectorError(
                f"attribute vectors must contain only 0 and 1 (method '{self.method}' learns "
                "0/1 attributes; method 'best' takes graded and not-known values)"
            )
        if (np.nan_to_num(v).sum(axis=1) == 0).any():
            raise AttributeVectorError(
                "an attribute vector must have at least one attribute set (a value above 0)"
            )
        return v

    def attribute_vector(self, attribute_names: Sequence[str]) -> np.ndarray:
        """0/1 vector from attribute names; unknown names raise AttributeVectorError."""
        vocab = self.registry.attribute_names
        unknown = [a for a in attribute_names if a not in vocab]
        if unknown:
            raise AttributeVectorError(
                f"unknown attribute(s): {'; '.join(map(suggest_attribute(vocab), unknown))}; "
                f"the attributes are: {', '.join(vocab)}"
            )
        return np.array([1.0 if a in set(attribute_names) else 0.0 for a in vocab], np.float32)

    def _require_fitted(self) -> None:
        if self.input_shape is None:
            raise NotFittedError(f"{type(self).__name__} is not fitted; call fit() first")

    # ------------------------------------------------------------ persistence
    @abstractmethod
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """(JSON-serialisable config and metadata, named float arrays) of the method's own parts."""

    @abstractmethod
    def set_state(self, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        """Restore what ``get_state`` returned."""


def same_vectors(vectors: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """(L,) bool: which rows of ``vectors`` equal ``vector``, a value not known (NaN) equal
    only to another value not known."""
    vectors, vector = np.asarray(vectors), np.asarray(vector)
    return ((vectors == vector) | (np.isnan(vectors) & np.isnan(vector))).all(axis=1)


def ranked(p: np.ndarray, k: int) -> np.ndarray:
    """(N, min(k, K)) column indices of each row's k largest values, largest first and, among
    equal values, the lower index first (the order of a stable sort).

    A row of many classes (30,000 known objects) is not sorted: for a few places (k <= 8)
    the largest is taken k times (``argmax`` gives the first of equal values), each a pass
    over the row, O(k K); for more, a partition finds the k-th largest value and only the
    values at least as large are sorted."""
    n, width = p.shape
    k = min(k, width)
    if width <= 8 * k + 64:
        return np.argsort(-p, axis=1, kind="stable")[:, :k]
    out = np.empty((n, k), np.int64)
    if k <= 8:
        rows, left = np.arange(n), np.array(p, np.float64)  # a copy: the places taken go
        for j in range(k):
            out[:, j] = left.argmax(axis=1)
            left[rows, out[:, j]] = -np.inf
        return out
    kth = np.partition(p, width - k, axis=1)[:, width - k]
    for i in range(n):
        candidates = np.flatnonzero(p[i] >= kth[i])
        out[i] = candidates[np.argsort(-p[i, candidates], kind="stable")[:k]]
    return out


def _top_k(p: np.ndarray, k: int, offset: int) -> tuple[np.ndarray, np.ndarray]:
    """Class index (plus ``offset``) and probability of each row's k largest, best first
    (``ranked``); a row of fewer than k classes is padded with index -1 and probability
    NaN."""
    order = ranked(p, k)
    index, value = order + offset, p[np.arange(len(p))[:, None], order]
    missing = k - order.shape[1]
    if missing > 0:
        index = np.concatenate([index, np.full((len(p), missing), -1, np.int64)], axis=1)
        value = np.concatenate([value, np.full((len(p), missing), np.nan)], axis=1)
    return index, value


def _looks_like_trials(samples: Any) -> bool:
    """A RawTrial, a trial's JSON form, or a list whose first item is one of those."""
    if isinstance(samples, RawTrial) or (isinstance(samples, Mapping) and "fingers" in samples):
        return True
    if isinstance(samples, list | tuple) and samples:
        return _looks_like_trials(samples[0])
    return False


def check_groups(groups: Any, n: int) -> np.ndarray:
    """``groups`` as int64 (n,) with values 0 … G-1, every one used; InputShapeError if not."""
    try:
        g = np.asarray(groups)
    except (TypeError, ValueError):
        raise InputShapeError("groups must be an array of integers") from None
    if g.shape != (n,):
        raise InputShapeError(f"groups must have one entry per sample, shape ({n},), got {g.shape}")
    if g.dtype.kind not in "iu" and not (
        g.dtype.kind == "f" and np.isfinite(g).all() and (g == np.round(g)).all()
    ):
        raise InputShapeError(f"groups must be integers, got {g.dtype.name} values")
    g = g.astype(np.int64)
    if g.min() < 0:
        raise InputShapeError(f"groups must be 0 … G-1, got {int(g.min())}")
    used = np.bincount(g)
    if (used == 0).any():
        missing = int(np.argmin(used))
        raise InputShapeError(
            f"groups must number the groups 0 … G-1 with every group used; group {missing} "
            f"has no sample (G = {len(used)})"
        )
    return g


def group_mean(values: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """float64 mean of ``values`` (N, ...) over the rows of each group 0 … n_groups-1."""
    values = np.asarray(values, np.float64)
    out = np.zeros((n_groups, *values.shape[1:]))
    np.add.at(out, groups, values)
    counts = np.bincount(groups, minlength=n_groups).astype(np.float64)
    return out / counts.reshape(-1, *([1] * (values.ndim - 1)))


def fuse_groups(
    groups: np.ndarray,
    scores: np.ndarray,
    known_p: np.ndarray,
    novel_p: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The evidence of each group's samples as one answer (rule ``FUSION_RULE``, "mean"):
    the mean of the novelty scores, of the known-class probabilities and of the
    novel-class probabilities over the group's samples (each mean of probabilities is a
    distribution again). On the BioTac pilot's validation trials, fusing the two fingers by
    the product of their probabilities instead gave the same trial accuracy for ``best``
    and differed by a few hundredths either way for the other methods (docs/RESULTS.md);
    the mean is kept: one finger that is confidently wrong cannot veto the other."""
    n_groups = int(groups.max()) + 1
    return (
        group_mean(scores, groups, n_groups),
        group_mean(known_p, groups, n_groups),
        None if novel_p is None else group_mean(novel_p, groups, n_groups),
    )


def suggest_attribute(vocabulary: Sequence[str]) -> Callable[[Any], str]:
    """An unknown attribute name with the vocabulary's closest ones, for a typo."""

    def named(name: Any) -> str:
        close = difflib.get_close_matches(str(name), vocabulary, n=2, cutoff=0.6)
        return f"{name!r} (did you mean {' or '.join(map(repr, close))}?)" if close else repr(name)

    return named
