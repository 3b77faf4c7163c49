"""``auto``: the method that measures best on a probe of the training data itself.

No candidate holds everywhere (docs/RESULTS.md, docs/BENCHMARKS.md): ``prototypes`` keeps
shrinkage LDA's accuracy on thousands of simulated objects where ``best``'s forest falls
apart, and ``best`` detects novel PHAC-2 objects better. So a fit first measures each
candidate on its own training data and then fits the winner on all of it:

1. up to ``probe_classes`` classes with at least ``PROBE_MIN_TRIALS`` whole trials are
   drawn at random (a class of fewer cannot give a trial to the probe and keep two for its
   candidates' own calibration);
2. each of ``probe_folds`` folds sets apart ``probe_novel`` of them as pseudo-novel objects,
   whole (the next ones in the draw, so that folds share none while they last), holds out
   one whole trial of each remaining class, and fits every candidate on the rest;
3. a candidate scores its held-out trials' known accuracy plus the AUROC of its novelty
   score between those trials and the pseudo-novel objects' samples, averaged over folds;
   a candidate that cannot fit a fold scores nothing and its reason is kept;
4. the best score wins (ties go to the earlier candidate), and is fitted on everything.

Where the data hold no probe (fewer than 3 such classes, as in a service's first model of
2 classes with 2 enrolled samples each) or no candidate could be probed, ``unprobed`` wins
by rule: ``best``, which named held-out touches right 0.89-1.00 of the time on PHAC-2
where ``prototypes`` did 0.69-0.91, and 0.93-1.00 against 0.90-1.00 on the simulator,
with 2 samples a class of 2 to 5 classes (8 development seeds, the ones the rule was chosen on:
``python bench/research/small_catalogue.py``, docs/results/small_catalogue.json). A rule that
fails on the data falls back to the next candidate that fits.

The probe's fits leave out what it does not measure (``best``'s per-procedure models).
The choice rests on measurement, never on the catalogue's size: a probe is as large as the
catalogue up to ``probe_classes``. Raw trials are featurized once for the probe (by the
first candidate's featurizer) and the winner is fitted on the raw trials.

``fit`` returns the winner's fitted recognizer (a ``BestRecognizer`` or a
``PrototypeRecognizer``), not this object: its bundles load as that method, and its
``metrics["chosen_by"]`` records the choice (``choice_record``; ``GET /v1/models/active``
shows it): the method, why (``probe`` or ``rule``), the catalogue's size when it was made,
the probe's figures labelled with the probe's size, and the fitted model's own held-out
known accuracy at full size where the method measures one (``prototypes``' calibration
holds out a trial of every class), else ``null`` with the reason.
"""

from __future__ import annotations

import logging
import time
from typing import Any, ClassVar

import numpy as np
from sklearn.metrics import roc_auc_score

from app.data.biotac_dataset import BioTacDataset
from app.data.dataset import DatasetError, TactileDataset
from app.framework.defaults import AUTO
from app.framework.errors import FrameworkError
from app.framework.params import Constraint, Hyperparameters, between, check, integer
from app.framework.recognizer import TactileRecognizer

log = logging.getLogger(__name__)

CANDIDATES = ("prototypes", "best")
# parts a probe does not measure, left out of its fits: answers from some procedures
PROBE_ONLY_PARAMS = {"best": {"by_procedure": False}}
#: whole trials a class needs to enter the probe: one held out, two left to fit on
PROBE_MIN_TRIALS = 3
#: the candidate chosen where the data hold no probe (module docstring)
UNPROBED = "best"


class MethodChoice(Hyperparameters):
    """Chooses among ``candidates`` by a probe of the training data (module docstring).

    Parameters
    ----------
    seed : int, default 0
        Draws the probe's classes and held-out trials, and seeds every candidate.
    candidates : tuple of str, default ("prototypes", "best")
        Registered method names, in order of preference on a tie (both perfect, as on
        objects far apart): ``prototypes`` first, since it fits and serves at a fraction of
        ``best``'s memory (docs/BENCHMARKS.md).
    probe_classes : int, default 100
        At most this many classes enter the probe.
    probe_novel : float, default 0.2
        The share of the probe's classes held out whole as pseudo-novel objects.
    probe_folds : int, default 3
        Folds, each with its own pseudo-novel classes and one held-out trial per class.
    n_jobs : int or None, default 1
        Passed to each candidate.
    params : dict or None, default None
        Each candidate's own hyper-parameters, by method name.
    unprobed : str or None, default None
        The candidate chosen by rule where the data hold no probe (module docstring);
        None: ``best`` where it is a candidate, else the first candidate.
    """

    method: ClassVar[str] = AUTO
    # every candidate shares these (checked in tests/methods/test_choice.py), so a service
    # can ask them of this class before its first model exists
    novel_part_separable: ClassVar[bool] = True
    learns_classes_from_samples: ClassVar[bool] = True
    graded_attributes: ClassVar[bool] = True
    attributes_separable: ClassVar[bool] = True
    learns_known_incrementally: ClassVar[bool] = True

    _parameter_constraints: ClassVar[dict[str, Constraint]] = {
        "probe_classes": integer(3),
        "probe_novel": between(0.0, 1.0),
        "probe_folds": integer(1),
    }

    def __init__(
        self,
        seed: int = 0,
        candidates: tuple[str, ...] | list[str] = CANDIDATES,
        probe_classes: int = 100,
        probe_novel: float = 0.2,
        probe_folds: int = 3,
        n_jobs: int | None = 1,
        params: dict[str, dict[str, Any]] | None = None,
        unprobed: str | None = None,
    ) -> None:
        self.seed = seed
        self.candidates = candidates
        self.probe_classes = probe_classes
        self.probe_novel = probe_novel
        self.probe_folds = probe_folds
        self.n_jobs = n_jobs
        self.params = params
        self.unprobed = unprobed

    def _validate_params(self) -> None:
        from app.framework.registry import METHODS

        super()._validate_params()
        check(len(self.candidates) >= 1, "candidates must name at least one method")
        unknown = [c for c in self.candidates if c not in METHODS or c == self.method]
        check(
            not unknown,
            f"candidates must be registered methods other than 'auto', got {unknown}",
        )
        extra = sorted(set(self.params or {}) - set(self.candidates))
        check(not extra, f"params name methods that are not candidates: {extra}")
        check(
            self.unprobed is None or self.unprobed in self.candidates,
            f"unprobed must be one of the candidates {list(self.candidates)}, "
            f"got {self.unprobed!r}",
        )

    def _make(self, name: str, probe: bool = False) -> TactileRecognizer:
        from app.framework.registry import method_class

        cls = method_class(name)
        shared = {"seed": self.seed, "n_jobs": self.n_jobs}  # where the method takes them
        params = {k: v for k, v in shared.items() if k in cls._get_param_names()}
        params.update((self.params or {}).get(name, {}))
        if probe:
            params.update(PROBE_ONLY_PARAMS.get(name, {}))
        return cls(**params)

    def fit(self, dataset: TactileDataset | BioTacDataset, progress: bool = False) -> Any:
        """The winning candidate fitted on ``dataset`` (see the module docstring)."""
        self._validate_params()
        if not isinstance(dataset, TactileDataset | BioTacDataset):
            raise FrameworkError(
                "fit takes a TactileDataset (fixed-shape samples) or a BioTacDataset (raw "
                f"trials), got {type(dataset).__name__}"
            )
        t0 = time.perf_counter()
        self.probed_classes_ = 0
        scores = self.probe(dataset) if len(self.candidates) > 1 else {}
        scored = [c for c in self.candidates if "score" in scores.get(c, {})]
        if scored:
            order = sorted(scored, key=lambda c: -scores[c]["score"])  # stable: ties keep order
            reason = "probe"
        else:
            first = self.unprobed or (UNPROBED if UNPROBED in self.candidates else None)
            first = first or self.candidates[0]
            order = [first, *(c for c in self.candidates if c != first)]
            reason = "rule" if len(self.candidates) > 1 else "only candidate"
        probe_s = time.perf_counter() - t0
        failed: dict[str, str] = {}
        for winner in order:
            try:
                model = self._make(winner).fit(dataset, progress=progress)
                break
            except (DatasetError, FrameworkError) as error:
                # a rule's choice that cannot fit these data gives way to the next candidate
                failed[winner] = str(error)
                if reason == "probe" or winner == order[-1]:
                    raise
        log.info("auto: %s chosen by %s (%s) in %.1f s", winner, reason, scores, probe_s)
        model.metrics = {  # kept in its bundle
            **model.metrics,
            "chosen_by": choice_record(
                winner, reason, dataset, scores, probe_s, self.probed_classes_, model
            )
            | ({"candidates_failed": failed} if failed else {}),
        }
        return model

    def probe(self, dataset: TactileDataset | BioTacDataset) -> dict[str, dict[str, Any]]:
        """Each candidate's probe figures: ``known_acc``, ``nd_auroc`` and their sum
        ``score``, means over the folds, or ``error`` where the candidate could not fit a
        fold; empty when the data hold no probe (fewer than three classes with
        ``PROBE_MIN_TRIALS`` trials or more). Sets ``probed_classes_``, how many classes it
        drew (0 without a probe)."""
        self.probed_classes_ = 0  # how many classes the probe drew (0: no probe)
        eligible = _eligible(dataset)
        if len(eligible) < 3:
            return {}
        if isinstance(dataset, BioTacDataset):
            from app.framework.tactile_image import featurize_dataset

            featurizer = self._make(self.candidates[0])._new_featurizer().fit(dataset.trials)
            dataset = featurize_dataset(dataset, featurizer, augment=False)
        rng = np.random.default_rng(self.seed)
        drawn = rng.permutation(eligible)[: self.probe_classes]
        self.probed_classes_ = len(drawn)
        n_novel = min(len(drawn) - 2, max(1, int(round(self.probe_novel * len(drawn)))))
        figures: dict[str, list[tuple[float, float]]] = {c: [] for c in self.candidates}
        errors: dict[str, str] = {}
        for fold in range(self.probe_folds):
            # each fold sets apart the next classes as novel, so that folds share none
            novel = np.roll(drawn, -fold * n_novel)[:n_novel]
            known = np.setdiff1d(drawn, novel)
            probe = dataset.select_classes(np.r_[known, novel])
            is_novel = probe.labels >= len(known)
            held = _one_trial_each(probe.trials, probe.labels, ~is_novel, rng)
            train = probe.subset(np.flatnonzero(~held & ~is_novel)).select_classes(
                np.arange(len(known))
            )
            x_known, y_known = probe.samples[held], probe.labels[held]
            x_novel = probe.samples[is_novel]
            truth = np.r_[np.zeros(len(x_known)), np.ones(len(x_novel))]
            for name in self.candidates:
                if name in errors:
                    continue
                try:
                    model = self._make(name, probe=True).fit(train)
                except (DatasetError, FrameworkError) as error:
                    errors[name] = str(error)
                    continue
                acc = float(np.mean(model.known_proba(x_known).argmax(axis=1) == y_known))
                score = np.r_[model.novelty_score(x_known), model.novelty_score(x_novel)]
                figures[name].append((acc, float(roc_auc_score(truth, score))))
        out: dict[str, dict[str, Any]] = {}
        for name, folds in figures.items():
            if name in errors:
                out[name] = {"error": errors[name]}
                continue
            acc, auroc = np.mean(folds, axis=0)
            out[name] = {"known_acc": float(acc), "nd_auroc": float(auroc)}
            out[name]["score"] = float(acc + auroc)
        return out


#: the probe's figures estimate the catalogue's own while it is at most this many times
#: the probe's size; past it known accuracy falls with the number of classes
#: (docs/BENCHMARKS.md: 0.95 on a 100-class probe, 0.609 at 30,000 objects)
PROBE_REPRESENTS = 2


def choice_record(
    method: str,
    reason: str,
    dataset: TactileDataset | BioTacDataset,
    scores: dict[str, dict[str, Any]],
    probe_seconds: float,
    probe_classes: int,
    model: TactileRecognizer,
) -> dict[str, Any]:
    """What ``metrics["chosen_by"]`` keeps of a choice (module docstring)."""
    n_classes = int(dataset.n_classes)
    record: dict[str, Any] = {
        "method": method,
        "reason": reason,
        "n_classes": n_classes,
        "n_samples": int(len(dataset)),
        "probe_classes": probe_classes,
        "probe": scores,
        "probe_seconds": round(probe_seconds, 1),
    }
    held_out = model.metrics.get("probe_known_acc")  # prototypes: a trial of each class
    if held_out is not None:
        record["full_size_known_acc"] = float(held_out)
    else:
        record["full_size_known_acc"] = None
        record["full_size_note"] = (
            f"{method} measures no held-out known accuracy at full size"
            if scores and n_classes > PROBE_REPRESENTS * probe_classes
            else "the probe's figures are at the catalogue's size"
            if scores
            else "no probe: the data hold too few classes with enough trials"
        )
    if scores and n_classes > PROBE_REPRESENTS * probe_classes:
        record["probe_note"] = (
            f"measured on a probe of {probe_classes} of {n_classes} classes; accuracy falls "
            "as classes are added, so the probe's figures overstate the catalogue's"
        )
    return record


def _eligible(dataset: TactileDataset | BioTacDataset) -> np.ndarray:
    """The classes with at least ``PROBE_MIN_TRIALS`` whole trials."""
    labels = np.asarray(dataset.labels)
    trials = np.asarray(dataset.trial_ids if isinstance(dataset, BioTacDataset) else dataset.trials)
    n_trials = np.array(
        [len(np.unique(trials[labels == c])) for c in range(dataset.n_classes)], dtype=int
    )
    return np.flatnonzero(n_trials >= PROBE_MIN_TRIALS)


def _one_trial_each(
    trials: np.ndarray, labels: np.ndarray, among: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """(N,) bool: one whole trial, drawn at random, of each class of the rows ``among``."""
    held = np.zeros(len(trials), bool)
    for c in np.unique(labels[among]):
        rows = among & (labels == c)
        held |= rows & (trials == rng.choice(np.unique(trials[rows])))
    return held
