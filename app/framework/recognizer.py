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

``TactileRecognizer`` is built from parts in modules of their own, which never import
this one: the answers and their ranking (``app.framework.results``), the classes and the
novelty tuning it carries (``app.framework.state``), hyper-parameters
(``app.framework.params``), raw trials as input (``app.framework.raw_input``), groups
(``app.framework.fusion``), answers from some procedures
(``app.framework.some_procedures``) and enrolment (``app.framework.enrolment``). Every
name other code imports from here stays importable from here (``__all__``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Self

import numpy as np

from app.data.biotac import BioTacDataset
from app.data.dataset import TactileDataset
from app.data.procedures import ProcedureError, cell_name, named_list, present
from app.framework.enrolment import Enrolment, same_vectors, suggest_attribute
from app.framework.errors import (
    FrameworkError,
    InputKindError,
    InputShapeError,
    MissingProcedureError,
    NonFiniteInputError,
    NotFittedError,
    UnknownClassError,
    UnsupportedOperationError,
)
from app.framework.fusion import FUSION_RULE, check_groups, fuse_groups, group_mean
from app.framework.input_health import InputProfile
from app.framework.params import Hyperparameters
from app.framework.raw_input import (
    RAW_TRIALS,
    SAMPLES,
    looks_like_trials,
    takes_samples,
    takes_trials,
    trial_images,
)
from app.framework.results import (
    ABSTAIN,
    INPUT_OUTLIER,
    OUTLIER_POLICIES,
    ClassScore,
    Recognition,
    RecognitionBatch,
    check_outliers,
    one_row_batch,
    ranked,
    rows_batch,
)
from app.framework.runtime import configure_heap, ensure_threads_configured
from app.framework.some_procedures import (
    MIN_PROCEDURES,
    TARGET_CONFIDENCE,
    asks_next,
    by_procedures,
)
from app.framework.state import (
    DEFAULT_KNOWN_KEPT,
    KNOWN_KEPT,
    MODEL_DEFAULT,
    ClassRegistry,
    NoveltyTuning,
)

__all__ = [
    "ABSTAIN",
    "DEFAULT_KNOWN_KEPT",
    "FUSION_RULE",
    "INPUT_OUTLIER",
    "KNOWN_KEPT",
    "MIN_PROCEDURES",
    "MODEL_DEFAULT",
    "OUTLIER_POLICIES",
    "RAW_TRIALS",
    "SAMPLES",
    "TARGET_CONFIDENCE",
    "ClassRegistry",
    "ClassScore",
    "NoveltyTuning",
    "Recognition",
    "RecognitionBatch",
    "TactileRecognizer",
    "check_groups",
    "check_outliers",
    "fuse_groups",
    "group_mean",
    "ranked",
    "same_vectors",
    "suggest_attribute",
]


class TactileRecognizer(Hyperparameters, Enrolment, ABC):
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
        # the training samples' channel ranges (``app.framework.input_health``); None for a
        # model loaded from a bundle written before them: its answers' input health is None
        self.input_profile_: InputProfile | None = None

    # --------------------------------------------------------- hyper-parameters
    def _validate_params(self) -> None:
        """Check every hyper-parameter against ``_parameter_constraints``
        (``Hyperparameters``), and the ``featurizer_params`` options where the method has
        them; a subclass adds the checks that involve several parameters. Raises
        FrameworkError."""
        super()._validate_params()
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
        configure_heap()  # a fit's freed arrays go back to the system
        attributes = self._training_attributes(dataset)
        self.input_shape = dataset.input_shape
        self.featurizer_ = featurizer
        self.procedures = dataset.procedures
        self.input_profile_ = InputProfile.fit(dataset.samples)
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
        return takes_samples(self.input_shape)

    def _takes_trials(self) -> str:
        return takes_trials(self.input_shape)

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
        return trial_images(self.featurizer_, trials)

    def recognize_trials(
        self, trials: Any, top_k: int = 3, known_kept: float | None = None
    ) -> RecognitionBatch:
        """One answer per raw trial, from the images of all its fingers together (the
        ``groups`` fusion of ``recognize_batch``). Errors as ``trial_samples``."""
        images, index = self.trial_samples(trials)
        return self.recognize_batch(images, top_k, groups=index, known_kept=known_kept)

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
        return self._one_score(samples, self._known_proba, 1)

    def novel_proba(self, samples: np.ndarray) -> np.ndarray:
        if not self.registry.novel_names:
            raise UnknownClassError("the model has no novel classes yet")
        return self._one_score(samples, self._novel_proba, 2)

    def novelty_score(self, samples: np.ndarray) -> np.ndarray:
        return self._one_score(samples, self._novelty_score, 0)

    def _one_score(
        self, samples: Any, direct: Callable[[np.ndarray], np.ndarray], part: int
    ) -> np.ndarray:
        """One of ``_scores_from``'s answers (``part``: its index there) for validated
        ``samples``: ``direct`` where every sample is complete, else from the procedures
        each holds."""
        x, used = self._checked(samples)
        if used is None:
            return direct(x)
        return self._by_procedures(x, used, lambda x, keep: self._scores_from(x, keep)[part])

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

    #: ``part(rows, keep)`` on each group of rows that hold the same procedures
    _by_procedures = staticmethod(by_procedures)

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
        known_kept: float | None = None,
        outliers: str = ABSTAIN,
    ) -> list[Recognition]:
        """Fig. 1: ND(x) routes each sample (or each group, see ``recognize_batch``) to
        FC_Y or FC_Z. An input outlier's answer names no class unless ``outliers`` is
        ``"answer"`` (``app.framework.results``)."""
        check_outliers(outliers)
        batch = self.recognize_batch(samples, top_k, groups, target_confidence, known_kept)
        return batch.answers(outliers)

    def recognize_batch(
        self,
        samples: np.ndarray,
        top_k: int = 3,
        groups: np.ndarray | None = None,
        target_confidence: float = TARGET_CONFIDENCE,
        known_kept: float | None = None,
        touches: np.ndarray | None = None,
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

        ``known_kept`` routes by another operating point than the model's own threshold:
        the threshold that kept that share of held-out known samples known when the model
        was fitted (``threshold_keeping``). An answer that fuses touches reads the curve
        measured on held-out answers fusing as many (``NoveltyTuning.touches``), where
        fitting measured it: ``touches`` ((G,) ints) says how many each group fuses, by
        default its samples (one for each group of a raw-trial model: a trial). Every answer
        records the threshold it was routed by, the operating point and the curve's touches
        (``novelty_threshold``, ``known_kept``, ``calibrated_touches``).
        """
        if not 0.0 < float(target_confidence) <= 1.0:
            raise FrameworkError(f"target_confidence must lie in (0, 1], got {target_confidence}")
        # a bad share, or a model without a curve, refused before any work
        single = (
            self.novelty_threshold if known_kept is None else self.threshold_keeping(known_kept)
        )
        x, used = self._checked(samples)
        if used is None:
            scores, known_p, novel_p = self._all_scores(x)
        else:
            scores, known_p, novel_p = self._by_procedures(x, used, self._scores_from)
        g = None
        if groups is not None:
            g = check_groups(groups, len(x))
            scores, known_p, novel_p = fuse_groups(g, scores, known_p, novel_p)
            if used is not None:
                used = group_mean(used.astype(np.float64), g, int(g.max()) + 1) > 0
        threshold, calibrated = self._thresholds(known_kept, single, g, len(scores), touches)
        batch = self._batch(scores, known_p, novel_p, top_k, threshold)
        batch.__dict__.update(known_kept=known_kept, calibrated_touches=calibrated)
        self._add_input_health(batch, x, g)
        if used is None:
            return self._complete(batch)
        ask = asks_next(batch.top_probability[:, 0], used, target_confidence)
        batch.__dict__.update(
            procedures=self.procedures,
            procedures_used=used,
            next_procedure=self._next_procedures(known_p, used, ask),
        )
        return batch

    def _thresholds(
        self,
        known_kept: float | None,
        single: float,
        groups: np.ndarray | None,
        n: int,
        touches: np.ndarray | None,
    ) -> tuple[float | np.ndarray, np.ndarray | None]:
        """(threshold of each of the ``n`` answers, or one for all; the touches of the curve
        each was read off, None at the model's own threshold). ``single``: the threshold of
        single samples (the model's own where ``known_kept`` is None)."""
        if known_kept is None:
            return single, None
        tuning = self.novelty_tuning
        if groups is None or not tuning.touches:  # single samples, or one curve: one threshold
            return single, np.full(n, self._single_touches, np.int64)
        if touches is not None:
            count = np.asarray(touches, np.int64).reshape(-1)
            if count.shape != (n,) or (count < 1).any():
                raise FrameworkError(
                    f"touches must give each of the {n} groups a positive count, got "
                    f"{count.tolist()[:10]}"
                )
        elif self.featurizer_ is not None:
            count = np.ones(n, np.int64)  # a raw-trial model's group: one trial
        else:
            count = np.bincount(groups, minlength=n)
        if self.featurizer_ is None:
            count = np.where(count == 1, 0, count)  # one sample: the single samples' curve
        kinds = np.unique(count)
        threshold, calibrated = np.empty(n), np.empty(n, np.int64)
        for c in kinds.tolist():
            rows = count == c
            threshold[rows], k = tuning.threshold_keeping_touches(known_kept, c)
            calibrated[rows] = k if k else self._single_touches
        return threshold, calibrated

    @property
    def _single_touches(self) -> int:
        """``calibrated_touches`` of the single samples' curve: 1 where a sample is a touch,
        0 for a raw-trial model (its samples are images, not trials)."""
        return 0 if self.featurizer_ is not None else 1

    def threshold_keeping(self, known_kept: float) -> float:
        """The novelty threshold that kept the share ``known_kept`` (in (0, 1)) of held-out
        known samples known when the model was fitted, read off its calibration curve
        (``novelty_tuning``); a sample scoring above it is novel. The model's own
        ``novelty_threshold`` is one point of the same curve."""
        if not 0.0 < float(known_kept) < 1.0:
            raise FrameworkError(f"known_kept must lie in (0, 1), got {known_kept}")
        if self.novelty_tuning is None:
            raise UnsupportedOperationError(
                f"this {type(self).__name__} holds no calibration of its novelty scores: "
                "it answers at its own threshold only (known_kept cannot move it)"
            )
        return self.novelty_tuning.threshold_keeping(float(known_kept))

    def operating_point(
        self, known_kept: float | None = None, default: float | None = DEFAULT_KNOWN_KEPT
    ) -> float | None:
        """The share of known touches an answer is routed by (``recognize_batch``'s
        ``known_kept``): ``known_kept`` where one is asked for; else ``default`` (the
        served default, ``DEFAULT_KNOWN_KEPT``) where the model holds a calibration curve;
        else None, the model's own threshold (a model without a curve)."""
        if known_kept is not None:
            return known_kept
        return default if self.novelty_tuning is not None else None

    def input_outlier_score(self, samples: Any) -> np.ndarray:
        """(N,) how far each sample lies outside the training data's channel ranges, in
        training IQRs (``app.framework.input_health``; above the profile's ``threshold`` it
        is an outlier); NaN for every sample of a model without an input profile."""
        x, _ = self._checked(samples)
        if self.input_profile_ is None:
            return np.full(len(x), np.nan)
        return self.input_profile_.score(x)

    def _add_input_health(
        self, batch: RecognitionBatch, x: np.ndarray, groups: np.ndarray | None
    ) -> None:
        """Set ``batch``'s input health from its samples ``x``: with ``groups``, a group's
        score is the largest of its samples' (one failing finger makes the trial's answer
        an outlier). Left None where the model holds no input profile."""
        if self.input_profile_ is None:
            return
        statistics = self.input_profile_.features(x)
        score = self.input_profile_.score_features(statistics)
        if groups is not None:
            fused = np.zeros(len(batch))
            np.maximum.at(fused, groups, score)
            score = fused
        batch.__dict__.update(
            input_outlier_score=score,
            input_outlier=self.input_profile_.is_outlier(score),
            input_statistics=statistics,
        )

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
        threshold: float | None = None,
    ) -> RecognitionBatch:
        """The answers from the scores: route each row by its novelty score (novel above
        ``threshold``, by default the model's), rank the top k of the classifier that
        answers it. One row takes ``_one_row``: the same bits, without the machinery for
        many rows (about half the cost for one sample)."""
        if len(scores) == 1:
            return self._one_row(scores, known_p, novel_p, top_k, threshold)
        return self._rows(scores, known_p, novel_p, top_k, threshold)

    def _one_row(
        self,
        scores: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
        top_k: int,
        threshold: float | None = None,
    ) -> RecognitionBatch:
        """``_rows`` for a batch of one row, bit for bit (``one_row_batch``)."""
        reg = self.registry
        return one_row_batch(
            scores,
            known_p,
            novel_p,
            top_k,
            self.novelty_threshold if threshold is None else threshold,
            reg.known_names,
            reg.novel_names,
        )

    def _rows(
        self,
        scores: np.ndarray,
        known_p: np.ndarray,
        novel_p: np.ndarray | None,
        top_k: int,
        threshold: float | None = None,
    ) -> RecognitionBatch:
        """``_batch`` for any number of rows (``rows_batch``; the reference ``_one_row``
        must match)."""
        reg = self.registry
        return rows_batch(
            scores,
            known_p,
            novel_p,
            top_k,
            self.novelty_threshold if threshold is None else threshold,
            reg.known_names,
            reg.novel_names,
        )

    # --------------------------------------------------------------- enrolment
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
        if not isinstance(samples, np.ndarray) and looks_like_trials(samples):
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
            what = "infinity" if infinite.any() else "NaN"
            hit = np.isinf(x[bad]) if infinite.any() else np.isnan(x[bad])
            cell = cell_name(bad, tuple(map(int, np.unravel_index(int(hit.argmax()), hit.shape))))
            raise NonFiniteInputError(f"sample {bad} contains {what}: cell {cell} is {what}")
        try:
            used = present(x, self.procedures)
        except ProcedureError as exc:
            raise MissingProcedureError(str(exc)) from None
        if not partial or not self.answers_from_some_procedures:
            i = int((~used.all(axis=1)).argmax())
            lacking = [p for p, u in zip(self.procedures, used[i], strict=True) if not u]
            if partial:
                why = f"sample {i} lacks {', '.join(lacking)}: method '{self.method}' answers "
                raise MissingProcedureError(why + "from every procedure")
            raise MissingProcedureError(
                f"enrolment takes whole samples: {named_list(lacking, 'procedure')} of sample "
                f"{i} {'is' if len(lacking) == 1 else 'are'} missing (NaN throughout); samples "
                "learnt by the model need every procedure"
            )

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
