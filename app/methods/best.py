"""The ``best`` method: the recognizer that measured best on PHAC-2's static features.

Every sample is a flat vector (a C x T tactile image is flattened) scaled by
``RobustInputScaler`` (signed log1p, median/IQR, clipped); PHAC-2's features
reach 1e10.

- Known classes (FC_Y): an extra-trees forest on the scaled inputs; ``known_proba``
  is its class distribution.
- Novelty ND(x): ``1 - max p`` of the forest plus ``knn_weight`` x the log distance
  to the nearest training sample and ``top_weight`` x the log distance to the
  nearest training sample of the top class, in a feature-weighted space (its top
  ``distance_components`` principal directions plus residual norms), each
  relative to the training set's own trial spacing (``known``). The threshold is
  tuned by the paper's Sect. VI-B protocol (``novelty_validation_split`` +
  ``tune_threshold``) on probe models that never see the validation objects;
  ``tuning_rounds`` such splits (different validation objects) are pooled into
  one ``tune_threshold`` call, which steadies the threshold. The deployed model
  covers every known class and keeps it.
- Zero-shot (FC_Z from attributes): Direct Attribute Prediction with one
  L2-regularised logistic regression per attribute (``attributes``), its log scores
  plus ``sae_temperature`` x the cosine between the sample projected by a semantic
  autoencoder (Kodirov et al., 2017; ``sae_lambda``) and each novel class's attribute
  vector: a product of the two posteriors. 0 for ``sae_lambda`` leaves DAP alone.
- One-shot: a sample's *signature* is its known-class posterior, L2-normalised:
  which known objects it feels like. A novel class with real samples gets the
  mean signature of its samples as prototype, and samples are matched by cosine
  similarity (softmax over ``shot_temperature``). Classes without samples keep
  their zero-shot probability; the classes with samples share the rest, bounded by
  ``shot_margin``: they keep it only where the touch's signature is closer to theirs, by
  ``shot_margin / n`` for a class of n samples, than to the nearest known class's (the
  rest goes back to the classes without samples).

The forest is stored as plain arrays (``forest``), like every other part, so
model bundles need no pickle, and enrolment never retrains it: ``add_novel_classes`` only scores the
new attribute vectors and ``add_one_shot`` only computes signatures.

Without attributes (a dataset with M = 0, such as the BioTac pilot without objects.csv)
the forest, the novelty score and the one-shot signatures work as above; there is no
zero-shot part, and a novel class is enrolled from its samples alone
(``add_novel_classes_from_samples``): its probability is the one-shot softmax over the
novel classes' signature prototypes.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from tqdm import tqdm

from app.data.dataset import DatasetError, TactileDataset
from app.framework.errors import FrameworkError
from app.framework.one_shot import bounded_shots, shot_penalty
from app.framework.params import either, integer, number, one_of
from app.framework.progress import bar_disabled
from app.framework.recognizer import TactileRecognizer
from app.framework.runtime import ensure_threads_configured
from app.framework.scaling import flatten
from app.methods.attributes import (
    LinearAttributeModel,
    softmax,
)
from app.methods.by_procedure import ProcedureModels
from app.methods.described import DescribedClasses, check_known_classes
from app.methods.known import CUES, KnownModel, relabelled
from app.methods.small_batch import ScoringConstants, SmallBatchScorer

#: ``shot_margin``'s default (docs/RESULTS.md, "One-shot classes and other objects' touches")
SHOT_MARGIN = 0.0


def signatures(known_proba: np.ndarray) -> np.ndarray:
    """Known-class posteriors scaled to unit length (the one-shot embedding)."""
    p = np.asarray(known_proba, np.float64)
    return p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)


class BestRecognizer(DescribedClasses, TactileRecognizer):
    """The ``best`` method; the module docstring describes its parts.

    Parameters
    ----------
    seed : int, default 0
        Seed of the forests and of the Sect. VI-B choice of validation objects (tuning
        round r draws with ``seed + r``).
    n_estimators : int, default 100
        Trees in the extra-trees forest that classifies the known objects (FC_Y), and
        in each probe forest of the novelty tuning. A positive integer.
    max_features : {"sqrt", "log2"} or float, default "sqrt"
        Features each split of a tree draws from, as scikit-learn's
        ``ExtraTreesClassifier`` takes it: "sqrt" or "log2" of the number of input
        features, a count (int) or a fraction (float).
    attribute_samples : int, default 50000
        The attribute classifiers and the autoencoder learn from at most this many training
        samples, drawn at random (seeded by ``seed``): the 19 logistic regressions on all
        240,000 samples of 30,000 simulated objects took longer than the forest. PHAC-2's
        600 samples and the simulator up to 5,000 objects are below it. 0 takes every
        sample. A non-negative integer.
    attribute_C : float, default 0.1
        Inverse strength of the L2 penalty of the logistic regressions that predict
        each attribute from a sample (DAP's attribute classifiers). Positive.
    dap_clip : float, default 0.02
        DAP clips every attribute probability, and the attribute prior, to
        [dap_clip, 1 - dap_clip], so that no single attribute classifier can veto a
        novel class alone. In (0, 0.5).
    shot_temperature : float, default 0.05
        Temperature of the softmax over the cosine similarities between a sample's
        signature and the prototypes of the novel classes that have real samples
        (one-shot learning); smaller is sharper. Positive.
    shot_margin : float or None, default 0.0
        How much closer (in cosine, before ``shot_temperature``) a touch's signature must
        lie to the prototype of a novel class learnt from n samples than to the nearest
        known class's signature (the unit vector of that class), less ``shot_margin / n``,
        for the class to keep the probability it shares with the other classes with
        samples; what it gives up goes to the novel classes without samples (described
        ones), in proportion to their zero-shot probability. Without it a class enrolled
        from one sample and no description, whose zero-shot score is neutral, took a third
        of the described objects' touches (``bench/one_shot_swallow.py``). None: no bound, as
        before 2026-11-28. Of 0 to 0.3, 0 answered the novel objects' touches best
        (described objects' and one-shot objects' recall averaged, on PHAC-2 and the
        simulator, split seed 20; ``bench.one_shot_swallow``): the comparison with the
        nearest known class alone bounds the class, and every margin cost more of its own
        touches than it saved of others'. Non-negative, or None.
    knn_weight : float, default 0.1
        Weight, in the novelty score ND(x), of the log distance to the nearest
        training sample (relative to the training set's own trial spacing), added to
        ``1 - max p`` of the forest. Non-negative; 0 drops the cue.
    top_weight : float, default 0.1
        Weight, in ND(x), of the log distance to the nearest training sample of the
        forest's top class. Non-negative; 0 drops the cue.
    novelty_val_fraction : float, default 0.1
        Share of the known objects that act as validation-novel objects (Y_val of
        Sect. VI-B) when the novelty threshold is tuned. In (0, 1).
    novelty_holdout_trials : int, default 1
        Whole trials of every other known object held out as its known validation
        samples (X_te of Sect. VI-B) in that tuning. A positive integer.
    tuning_rounds : int, default 3
        Sect. VI-B splits, each with other validation objects and a probe model of its
        own, whose scores are pooled into one threshold choice (steadier than one
        split). A positive integer.
    tuning_objects : int, default 100
        The rounds stop early once their validation objects number at least this many
        (one round at 1,000 known objects and more, all of them on PHAC-2's 60): a probe
        model costs as much as the deployed one, and hundreds of validation objects
        already steady the threshold. 0 runs every round.
    distance_components : int, default 64
        The distances of ``knn_weight`` and ``top_weight`` are measured on this many
        principal directions of the feature-weighted training samples plus the norm of
        the rest; 0 measures them exactly in the full space. A non-negative integer.
    sae_lambda : float, default 400.0
        λ of the semantic autoencoder (Kodirov et al., 2017) that projects samples onto
        attribute space for zero-shot scores, beside DAP; 0 leaves DAP alone. A
        non-negative number.
    forest_grower : {"gini", "sklearn"}, default "gini"
        How the forests are grown (``FlatForest.grow``). "gini": extremely randomised
        trees with the exact Gini criterion, compiled (``app.methods.gini_trees``), at a
        cost that does not depend on the number of classes, each leaf then given the class
        distribution of the training samples that reach it. "sklearn": scikit-learn's
        extra trees, as ``best`` grew them before 2026-11-27 (``forest_codes``). At 3,000
        simulated objects "gini" grows a per-procedure forest in about half the time
        (docs/BENCHMARKS.md "Scale in objects").
    forest_codes : int, default 32
        With ``forest_grower`` "sklearn": the forest is grown as scikit-learn's extra-trees
        regressor on a random Gaussian code of this many dimensions per class, its leaves
        then given the class distribution of the training samples that reach them: time
        and memory grow with the samples, not with samples x classes. 0 grows
        scikit-learn's extra-trees classifier instead, which keeps a class distribution in
        every node (out of memory near 2,000 objects on 24 GB). A non-negative integer.
    approximate_above : int, default 20000
        Above this many training samples the nearest-sample distances of the novelty score
        are found through an HNSW graph (``app.methods.neighbours``) instead of by
        comparing each sample with all of them; 0 always compares exactly. A non-negative
        integer.
    sae_temperature : float, default 10.0
        Weight of the autoencoder's cosine between a sample's projection and a novel
        class's attribute vector, added to DAP's log scores. A non-negative number.
    n_jobs : int or None, default 1
        Parallel jobs of scikit-learn when the forests are fitted, and attribute classifiers
        fitted at once (None: one, -1: every core); recognition never uses them.
    featurizer_params : dict or None, default None
        Options of the ``TactileImageFeaturizer`` fitted when ``fit`` is given raw BioTac
        trials (``app.framework.tactile_image.featurizer_from_params``: any of n_steps,
        n_components, phase_names, phase_rule, baseline, n_offsets, normalize); an option
        left out (all of them with None) takes the featurizer's default (8 readings x 3
        phases x 30 steps), except ``n_offsets``, 1 here: each training finger once, not at
        the paper's 5 sub-sampling offsets. On validation trials of the BioTac pilot the
        forest carried objects across grip pressures worse the more offsets it was trained
        on (docs/RESULTS.md). Unused when ``fit`` is given fixed-shape samples.
    by_procedure : bool, default True
        Where the training samples name two or more exploratory procedures
        (``TactileDataset.procedures``), also fit one model per procedure on its block of the
        samples (``app.methods.by_procedure``), so that a sample lacking some procedures is
        answered from those it holds and every answer says which procedure to do next.
        False answers complete samples only.
    procedure_estimators : int or None, default None
        Trees of each per-procedure model (``by_procedure``), at most ``n_estimators``;
        None: ``n_estimators``. A per-procedure tree has about as many nodes as a
        whole-model tree (trees grow until their leaves are pure, whatever the features), so
        P per-procedure models of ``n_estimators`` trees make the bundle and a promotion
        about 1 + P times the whole model's alone. Measured with ``forest_grower``
        "sklearn" (1feb499): 50 halves what the per-procedure models cost; on PHAC-2's
        development splits (seeds 1-2, 10 splits, the default stopping rule;
        ``bench/research/explore_stopping.py --params``) it answered as 100 did (known_acc
        -0.009 from all procedures with either; 25 trees: -0.017), but on the reported
        splits (``evaluate --procedures``, seed 1000, 50 splits) the rule's known_acc fell
        from 0.977 to 0.973, beyond the 0.01 from all procedures the rule is held to. At
        3,000 simulated objects 50 trees took the fit from 165 to 120 s, and the known-object
        accuracy from one procedure alone from 0.052 to 0.038 (0.074 to 0.054 with objects
        as far apart as PHAC-2's; ``bench.scale --param procedure_estimators=50``).
        So the default keeps every tree, and a catalogue whose fit must be cheaper sets it.
    """

    method = "best"
    novel_part_separable = True  # enrolments never touch the forest or the attribute models
    graded_attributes = True  # soft targets for DAP, imputed values for the autoencoder
    attributes_separable = True  # a new vocabulary refits the attribute models, not the forest
    learns_known_incrementally = True  # promotion counts samples into the forest's leaves
    learns_classes_from_samples = True  # one-shot signatures need no attribute
    _featurizer_defaults = {"n_offsets": 1}  # see featurizer_params
    #: batches of at most this many samples take ``SmallBatchScorer`` (the same bits with a
    #: fraction of the per-call overhead, which dominates for a few samples); 0 forces the
    #: general path everywhere
    small_batch_max = 32

    _parameter_constraints = {
        "n_estimators": integer(1),
        "max_features": either(
            one_of(("sqrt", "log2")),
            number(0, allow_bool=False),
            must="be 'sqrt', 'log2' or a positive number",
        ),
        "attribute_C": number(0),
        "attribute_samples": integer(0, "be a non-negative integer (0 = every sample)"),
        "dap_clip": number(0, 0.5),
        "shot_temperature": number(0),
        "shot_margin": either(
            one_of((None,)),
            number(0, include_low=True, allow_bool=False, finite=True),
            must="be None or a non-negative number",
        ),
        "novelty_val_fraction": number(0, 1),
        "novelty_holdout_trials": integer(1),
        "knn_weight": number(0, include_low=True, allow_bool=False),
        "top_weight": number(0, include_low=True, allow_bool=False),
        "tuning_rounds": integer(1),
        "tuning_objects": integer(0, "be a non-negative integer (0 = every round)"),
        "forest_grower": one_of(("gini", "sklearn")),
        "forest_codes": integer(0, "be a non-negative integer (0 = classifier)"),
        "approximate_above": integer(0, "be a non-negative integer (0 = exact)"),
        "distance_components": integer(
            0, "be a non-negative integer (0 = exact)", allow_bool=False
        ),
        "sae_lambda": number(0, include_low=True, allow_bool=False, finite=True),
        "sae_temperature": number(0, include_low=True, allow_bool=False, finite=True),
        "by_procedure": one_of((True, False), "be true or false"),
        "procedure_estimators": either(
            one_of((None,)), integer(1), must="be None or a positive integer"
        ),
        # featurizer_params: checked by building the featurizer (TactileRecognizer)
    }

    def __init__(
        self,
        seed: int = 0,
        n_estimators: int = 100,
        max_features: str | float = "sqrt",
        attribute_C: float = 0.1,
        attribute_samples: int = 50000,
        dap_clip: float = 0.02,
        shot_temperature: float = 0.05,
        knn_weight: float = 0.1,
        top_weight: float = 0.1,
        novelty_val_fraction: float = 0.1,
        novelty_holdout_trials: int = 1,
        tuning_rounds: int = 3,
        tuning_objects: int = 100,
        distance_components: int = 64,
        forest_grower: str = "gini",
        forest_codes: int = 32,
        approximate_above: int = 20000,
        sae_lambda: float = 400.0,
        sae_temperature: float = 10.0,
        n_jobs: int | None = 1,
        featurizer_params: dict[str, Any] | None = None,
        by_procedure: bool = True,
        procedure_estimators: int | None = None,
        shot_margin: float | None = SHOT_MARGIN,
    ) -> None:
        super().__init__()
        self.seed = seed
        self.n_estimators = n_estimators
        self.max_features = max_features
        self.attribute_C = attribute_C
        self.attribute_samples = attribute_samples
        self.dap_clip = dap_clip
        self.shot_temperature = shot_temperature
        self.shot_margin = shot_margin
        self.knn_weight = knn_weight
        self.top_weight = top_weight
        self.novelty_val_fraction = novelty_val_fraction
        self.novelty_holdout_trials = novelty_holdout_trials
        self.tuning_rounds = tuning_rounds
        self.tuning_objects = tuning_objects
        self.distance_components = distance_components
        self.forest_grower = forest_grower
        self.forest_codes = forest_codes
        self.approximate_above = approximate_above
        self.sae_lambda = sae_lambda
        self.sae_temperature = sae_temperature
        self.n_jobs = n_jobs
        self.featurizer_params = featurizer_params
        self.by_procedure = by_procedure
        self.procedure_estimators = procedure_estimators

    def _cue_weights(self) -> np.ndarray:
        w = np.zeros(len(CUES))
        w[CUES.index("one_minus_maxp")] = 1.0
        w[CUES.index("log_knn1")] = float(self.knn_weight)
        w[CUES.index("log_top")] = float(self.top_weight)
        return w

    def _known_model(self, dataset: TactileDataset) -> KnownModel:
        return KnownModel.fit(
            dataset,
            self._cue_weights(),
            int(self.n_estimators),
            self.max_features,
            int(self.seed),
            self.n_jobs,
            int(self.distance_components),
            str(self.forest_grower),
            int(self.forest_codes),
            int(self.approximate_above),
        )

    # ----------------------------------------------------------------- fitting
    def _fit(self, dataset: TactileDataset, progress: bool) -> None:
        # fitting's own imports (scikit-learn): recognising from a bundle never needs them
        from app.framework.novelty import novelty_validation_split, tune_threshold

        check_known_classes(dataset, "best")
        t0 = time.perf_counter()
        timings: dict[str, float] = {}
        y = dataset.labels

        # Sect. VI-B: probe models fitted without validation objects and held-out trials, pooled.
        bar = tqdm(
            total=int(self.tuning_rounds) + 1,
            # a procedure model's dataset is named "<dataset>/<procedure>": its bar says so
            desc=f"best on {dataset.name}: probes, model",
            disable=bar_disabled(progress),
        )
        known_scores, val_scores, val_objects, known_trials = [], [], 0, []
        for r in range(int(self.tuning_rounds)):
            if 0 < self.tuning_objects <= val_objects:
                break
            fit_idx, known_idx, val_idx = novelty_validation_split(
                dataset,
                self.novelty_val_fraction,
                self.novelty_holdout_trials,
                seed=int(self.seed) + r,
            )
            if len(known_idx) == 0 or len(val_idx) == 0:
                continue
            probe = self._known_model(relabelled(dataset, fit_idx))
            known_scores.append(probe.novelty(flatten(dataset.samples[known_idx])))
            # object and trial of each: the curves of fused touches (``touch_curves``)
            known_trials.append(np.c_[y[known_idx], np.asarray(dataset.trials)[known_idx]])
            val_scores.append(probe.novelty(flatten(dataset.samples[val_idx])))
            val_objects += len(np.unique(dataset.labels[val_idx]))
            del probe  # gigabytes at thousands of objects: gone before the deployed fit
            bar.update()
        if not known_scores:
            raise DatasetError(
                "novelty tuning needs validation objects and held-out trials: give every known "
                "class at least 2 trials"
            )
        bar.total = bar.n + 1  # the rounds left out once enough validation objects were pooled
        bar.refresh()
        self.novelty_tuning = tune_threshold(
            np.concatenate(known_scores),
            np.concatenate(val_scores),
            known_trials=np.concatenate(known_trials),
        )
        self.novelty_threshold = float(self.novelty_tuning.threshold)
        timings["novelty_tuning_s"] = time.perf_counter() - t0

        # The deployed parts, on every known class.
        t = time.perf_counter()
        self.known_ = self._known_model(dataset)
        bar.update()
        bar.close()
        z = self.known_.cues_model.scaled(flatten(dataset.samples))
        timings["known_model_s"] = time.perf_counter() - t
        t = time.perf_counter()
        self._fit_attributes(z, y)
        timings["attributes_s"] = time.perf_counter() - t
        self.procedures_ = None
        self._reset_novel()
        if self.by_procedure and len(dataset.procedures) >= 2:
            t = time.perf_counter()
            # plain best parts, whatever subclass this is: a part sees one procedure's
            # block of the (featurized) samples, not what a subclass's fit expects
            trees = min(self.procedure_estimators or self.n_estimators, self.n_estimators)
            self.procedures_ = ProcedureModels.fit(
                dataset,
                lambda: BestRecognizer(
                    **{**self.get_params(), "by_procedure": False, "n_estimators": trees}
                ),
                progress,
            )
            timings["by_procedure_s"] = time.perf_counter() - t
        timings["total_s"] = time.perf_counter() - t0
        self.metrics = {
            "n_train_samples": int(len(dataset)),
            "n_known_classes": int(dataset.n_classes),
            "nd_known_kept": self.novelty_tuning.known_kept_at_threshold,
            "nd_val_novel": self.novelty_tuning.val_novel_at_threshold,
            "nd_val_auroc": self.novelty_tuning.auroc,
            "forest_nodes": self.known_.cues_model.forest.n_nodes,
            "novelty_tuning_rounds": len(known_scores),
            "timings": timings,
            "params": self.get_params(),
        }

    def _refit_attributes(self, dataset: TactileDataset) -> None:
        self._fit_attributes(
            self.known_.cues_model.scaled(flatten(dataset.samples)), dataset.labels
        )
        if self.procedures_ is not None:
            self.procedures_ = self.procedures_.refit_attributes(self, dataset)
        self.metrics = {**self.metrics, "n_attributes": len(self.registry.attribute_names)}

    def _grow_known(self, samples: np.ndarray, labels: np.ndarray) -> None:
        """Known classes learnt without a refit (a promotion): the forest keeps its splits, and
        the samples join the novelty cues'
        reference samples (``KnownModel.with_samples``); leaves the samples reach are grown
        further on the samples there, seen and new. The scaler, the feature weights, the
        novelty threshold and the attribute parts stay as fitted: the attribute classifiers
        and the autoencoder never see a promoted class's samples until the next full fit.
        ``metrics["n_grown_samples"]`` counts the samples learnt so since that fit."""
        grown = int(self.metrics.get("n_grown_samples", 0))
        self.known_ = self.known_.with_samples(
            flatten(samples),
            labels,
            len(self.registry.known_names),
            self.max_features,
            int(self.seed) + grown,  # another draw of split points for every promotion
        )
        self.metrics = {
            **self.metrics,
            "n_known_classes": len(self.registry.known_names),
            "n_grown_samples": grown + len(samples),
        }
        if self.procedures_ is not None:
            self.procedures_ = self.procedures_.grown(self, samples, labels)

    def _reset_novel(self) -> None:
        n_known = len(self.registry.known_names)
        self.shot_prototypes_ = np.zeros((0, n_known), np.float64)
        self.shot_has_ = np.zeros(0, bool)
        self.shot_counts_ = np.zeros(0, np.float64)
        self._small_batch = None  # its constants describe the novel part: built again on use
        if getattr(self, "procedures_", None) is not None:
            self.procedures_ = self.procedures_.synced(self, lambda m, j: m._reset_novel())

    # --------------------------------------------------------------- inference
    def _known_proba(self, samples: np.ndarray) -> np.ndarray:
        cues = self.known_.cues_model
        return cues.proba(cues.scaled(flatten(samples)))

    def _novelty_score(self, samples: np.ndarray) -> np.ndarray:
        return self.known_.novelty(flatten(samples))

    def _novel_proba(self, samples: np.ndarray) -> np.ndarray:
        cues = self.known_.cues_model
        z = cues.scaled(flatten(samples))
        return self._novel_from(z, cues.proba(z) if self.shot_has_.any() else None)

    def _novel_from(self, z: np.ndarray, known_p: np.ndarray | None) -> np.ndarray:
        if not self.has_attributes:
            # every novel class came from samples (add_novel_classes_from_samples): the
            # one-shot softmax over the signature prototypes is the whole answer
            sim = signatures(known_p) @ self.shot_prototypes_.T
            return softmax(sim / float(self.shot_temperature))
        p_zsl = self._zero_shot(z)
        has = self.shot_has_
        if not has.any():
            return p_zsl
        sim = signatures(known_p) @ self.shot_prototypes_[has].T
        p_shot = softmax(sim / float(self.shot_temperature))
        out = p_zsl.copy()
        out[:, has] = (1.0 - p_zsl[:, ~has].sum(axis=1, keepdims=True)) * p_shot
        return self._bounded(out, known_p)

    def _bounded(self, novel: np.ndarray, known_p: np.ndarray) -> np.ndarray:
        """``novel`` (the novel classes' probabilities, classes with samples sharing their
        zero-shot mass) bounded by ``shot_margin`` (``one_shot.bounded_shots``): a class with
        samples keeps its share where the touch's signature is closer to its prototype, less
        ``shot_margin / n``, than to the nearest known class's unit signature. The same
        numbers from either path (``_novel_from`` and the small-batch scorer's)."""
        has = self.shot_has_
        if self.shot_margin is None or not self.has_attributes or not has.any() or has.all():
            return novel
        sig = signatures(known_p)
        penalty = shot_penalty(self.shot_margin, self.shot_counts_[has])
        temperature = float(self.shot_temperature)
        shot = (sig @ self.shot_prototypes_[has].T - penalty) / temperature
        return bounded_shots(novel, has, shot, sig.max(axis=1) / temperature)

    def _attribute_proba(self, samples: np.ndarray) -> np.ndarray:
        # DAP's per-attribute classifiers: the same probabilities its zero-shot scores use
        return self.attributes_.predict_proba(self.known_.cues_model.scaled(flatten(samples)))

    def __getstate__(self) -> dict[str, Any]:
        # The small-batch scorer is a cache of this model, built on its first small batch:
        # a copy (each enrolment's, which drops it anyway) leaves it behind. Copying it, with
        # the reference samples' index, took 0.2-0.5 s an enrolment at 10,000 objects, on
        # every served model (bench.scale_service --in-process-only: docs/BENCHMARKS.md).
        state = self.__dict__.copy()
        state.pop("_small_batch", None)
        return state

    def _all_scores(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        if len(samples) <= self.small_batch_max:
            if getattr(self, "_small_batch", None) is None:
                self._small_batch = SmallBatchScorer(ScoringConstants.of(self))
            novelty, known, novel = self._small_batch.scores(flatten(samples))
            return novelty, known, None if novel is None else self._bounded(novel, known)
        z, known, novelty = self.known_.scores(flatten(samples))
        novel = self._novel_from(z, known) if self.registry.novel_names else None
        return novelty, known, novel

    # --------------------------------------------------------------- enrolment
    def _refit_novel(self, **options: Any) -> None:
        if options:
            raise FrameworkError(
                f"method '{self.method}' takes no enrolment options, got {sorted(options)}"
            )
        reg = self.registry
        protos = np.zeros((len(reg.novel_names), len(reg.known_names)), np.float64)
        has = np.zeros(len(reg.novel_names), bool)
        counts = np.zeros(len(reg.novel_names), np.float64)
        for i, name in enumerate(reg.novel_names):
            samples = reg.novel_samples.get(name)
            if samples is not None and len(samples):
                mean = signatures(self._known_proba(samples)).mean(axis=0)
                protos[i] = mean / max(float(np.linalg.norm(mean)), 1e-12)
                has[i], counts[i] = True, len(samples)
        self.shot_prototypes_, self.shot_has_, self.shot_counts_ = protos, has, counts
        self._small_batch = None
        if self.procedures_ is not None:
            self.procedures_ = self.procedures_.synced(self, lambda m, j: m._refit_novel())

    # ------------------------------------------------------- missing procedures
    @property
    def answers_from_some_procedures(self) -> bool:
        return getattr(self, "procedures_", None) is not None

    @property
    def first_procedure(self) -> str | None:
        if not self.answers_from_some_procedures:
            return None
        return self.procedures[self.procedures_.first]

    def _subset_scores(
        self, x: np.ndarray, keep: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        if not self.answers_from_some_procedures:
            return super()._subset_scores(x, keep)
        return self.procedures_.scores(x, keep, self.novelty_threshold)

    def _subset_attribute_proba(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        if not self.answers_from_some_procedures:
            return super()._subset_attribute_proba(x, keep)
        return self.procedures_.attribute_proba(x, keep)

    def _next_procedures(
        self, known_p: np.ndarray, used: np.ndarray, ask: np.ndarray
    ) -> np.ndarray:
        if not self.answers_from_some_procedures:
            return super()._next_procedures(known_p, used, ask)
        return self.procedures_.next_procedures(known_p, used, ask)

    # ------------------------------------------------------------ persistence
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        arrays: dict[str, np.ndarray] = {"prior": self.prior_}
        if self.sae_ is not None:
            arrays["sae"] = self.sae_
        for key, value in self.known_.get_state().items():
            arrays[f"known/{key}"] = value
        for key, value in self.attributes_.get_state().items():
            arrays[f"attributes/{key}"] = value
        meta = {
            "params": self.get_params(),
            "n_features": self.known_.cues_model.forest.n_features,
            "n_classes": self.known_.cues_model.forest.n_classes,
        }
        if self.procedures_ is not None:
            meta["by_procedure"], parts = self.procedures_.get_state()
            arrays.update({f"by_procedure/{key}": value for key, value in parts.items()})
        return meta, arrays

    def set_state(self, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ensure_threads_configured()  # the default thread limits, where no entry point chose them
        self.distance_components = 0  # bundles made before the parameter measure exact distances
        self.forest_grower = "sklearn"  # and those made before it grew scikit-learn's trees
        self.forest_codes = 0  # and those made before it hold a classifier's forest
        self.approximate_above = 0  # and no neighbour index
        self.tuning_objects = 0
        self.attribute_samples = 0
        self.sae_lambda = 0.0  # and those made before the autoencoder have none
        self.by_procedure = False  # and those made before per-procedure models answer whole samples
        self.procedure_estimators = None  # and those made before it gave them n_estimators trees
        names = self._get_param_names()
        for key, value in meta["params"].items():
            if key not in names:
                raise KeyError(f"unknown parameter {key!r} in the bundle")
            setattr(self, key, value)
        self._validate_params()

        def part(prefix: str) -> dict[str, np.ndarray]:
            return {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)}

        n_classes = int(meta["n_classes"])
        if n_classes != len(self.registry.known_names):
            raise ValueError(
                f"forest has {n_classes} classes but the bundle lists "
                f"{len(self.registry.known_names)} known classes"
            )
        n_features = int(np.prod(self.input_shape))
        if int(meta["n_features"]) != n_features:
            raise ValueError(
                f"forest expects {meta['n_features']} features, inputs have {n_features}"
            )
        self.known_ = KnownModel.from_state(
            part("known/"), self._cue_weights(), n_classes, n_features
        )
        self.attributes_ = LinearAttributeModel.from_state(part("attributes/"))
        self.prior_ = np.asarray(arrays["prior"], np.float64)
        self.sae_ = np.asarray(arrays["sae"], np.float32) if "sae" in arrays else None
        if self.sae_ is not None and self.sae_.shape != (len(self.prior_), n_features):
            raise ValueError(
                "semantic autoencoder does not match the inputs or the attribute vocabulary"
            )
        if self.attributes_.weights.shape[1] != n_features or len(self.prior_) != len(
            self.registry.attribute_names
        ):
            raise ValueError(
                "attribute model does not match the inputs or the attribute vocabulary"
            )
        self.procedures_ = None
        self._reset_novel()
        if self.registry.novel_names:
            self._refit_novel()
        if "by_procedure" in meta:
            self.procedures_ = ProcedureModels.from_state(
                meta["by_procedure"], part("by_procedure/"), self
            )
