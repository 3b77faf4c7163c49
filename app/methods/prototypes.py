"""The ``prototypes`` method: class prototypes in a discriminant space, searched by faiss.

Every sample is a flat vector scaled by ``RobustInputScaler`` (as ``best``), then mapped into
``SubclassEmbedding``'s space: whitened by the shrunk within-class covariance, each class
split into subclasses where its trials gather in several clusters (contact modes).

- Wide inputs (more than ``reduce_above`` features: a sensor of thousands of taxels) are
  first reduced to principal components within each procedure's block of features
  (``BlockPCA``); the probe chooses how many (``reduce_dims``), and whether classes are
  split into modes, by the held-out trials' mean log-probability of their own classes.
  Everything below (the space, the attribute parts, the marginals of missing procedures)
  then reads the components.

- Known classes (FC_Y): each subclass's mean is a prototype. A sample's class probabilities
  are the posterior of a mixture of isotropic Gaussians, one per prototype, with a variance
  ``tau (1 + 1/n)`` that counts the prototype's own uncertainty from its ``n`` samples, over
  the ``search_k`` nearest prototypes (``PrototypeSearch``: exact, or an HNSW graph at scale;
  the rest get probability 0). ``tau`` is chosen at fit by leave-one-trial-out: each
  calibration sample is scored against prototypes from which its own trial is removed,
  which costs one subtraction per sample, not a refit.
- Novelty ND(x): ``1 - max p`` plus ``distance_weight`` x the log squared distance to the
  nearest prototype per coordinate; the weight, unless given, is the one of
  ``DISTANCE_WEIGHTS`` that separates the probe's held-out known samples from its
  pseudo-novel ones best (AUROC). The threshold is an operating
  point: the ``known_kept`` quantile of the leave-one-trial-out scores of known samples, so
  about that share of known touches is kept known. The same pass scores every calibration
  sample without *any* prototype of its class (leave-one-class-out): those pseudo-novel
  scores give ``metrics["nd_val_auroc"]`` and what the threshold detects.
- Zero-shot: DAP and the semantic autoencoder on the scaled inputs, exactly as ``best``
  (``app.methods.attributes``).
- One-shot and samples-only classes: a novel class's samples give it a prototype, their
  mean in the same space, scored by the same Gaussian; classes without samples keep their
  zero-shot probability and those with samples share the rest, bounded by ``shot_margin``:
  they keep it only where the touch lies clearly closer to their prototype (by
  ``shot_margin / n`` for a class of n samples) than to its nearest known prototype (the
  rest goes back to the classes without samples).
- Promotion (``with_known_samples``): the class's samples become a prototype of their own
  beside the index, at no refit. The space, ``tau`` and the threshold stay as fitted.
- Missing procedures: the same Gaussian model's marginal over the features a sample holds
  (``SubclassEmbedding.marginal``), computed once per set of procedures and kept; the
  attribute parts read the missing features' conditional mean given the present ones.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from tqdm import tqdm

from app.data.dataset import DatasetError, TactileDataset
from app.data.procedures import block, seconds_of
from app.framework.errors import FrameworkError
from app.framework.one_shot import bounded_shots, shot_penalty
from app.framework.params import Constraint, either, integer, number, one_of
from app.framework.progress import bar_disabled
from app.framework.recognizer import TactileRecognizer
from app.framework.runtime import ensure_threads_configured
from app.framework.scaling import BlockPCA, RobustInputScaler, flatten
from app.methods.attributes import (
    LinearAttributeModel,
    softmax,
)
from app.methods.described import DescribedClasses, check_known_classes
from app.methods.embedding import SubclassEmbedding
from app.methods.prototype_search import PrototypeSearch
from app.methods.prototype_small_batch import PrototypeSmallBatch

#: the weights of the distance cue the probe chooses among (``distance_weight=None``)
DISTANCE_WEIGHTS = (0.0, 0.03, 0.1, 0.3, 1.0, 3.0, 100.0)
#: the temperatures tried at fit (times the whitened space's unit variance)
_TAUS = np.geomspace(0.05, 20.0, 49)
#: samples scored at a time where each is scored against every prototype (memory: rows x
#: prototypes x 8 bytes), and the samples the order of the procedures is measured on
_BLOCK = 1024
_ORDER_SAMPLES = 4096
#: training samples the input scaler's medians and quartiles are read from
_SCALER_SAMPLES = 50_000
#: a squared distance below this counts as this (a touch on a prototype: no log of 0)
_TINY = 1e-12
#: ``shot_margin``'s default (docs/RESULTS.md, "One-shot classes and other objects' touches")
SHOT_MARGIN = 20.0
#: shrinkages of the within-class correlations tried at fit, beside Ledoit-Wolf's own
_SHRINKAGES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


class PrototypeRecognizer(DescribedClasses, TactileRecognizer):
    """The ``prototypes`` method; the module docstring describes its parts.

    Parameters
    ----------
    seed : int, default 0
        Seeds the calibration samples, the rows Ledoit-Wolf's shrinkage reads and the
        attribute classifiers' sample.
    max_modes : int, default 3
        The most subclasses (contact modes) a class is split into; 1 never splits, which is
        shrinkage LDA's space with nearest-class-mean prototypes. A positive integer.
    split_ratio : float, default 0.7
        A class is split in two where the halves keep at most this share of its squared
        spread (``SubclassEmbedding``; one Gaussian cluster of 8 simulated samples keeps
        about 0.84, three modes about 0.49). In (0, 1).
    reduce_above : int, default 1024
        Inputs of more features than this are reduced to principal components
        (``app.framework.scaling.BlockPCA``, within each procedure's block of features)
        before the within-class covariance is estimated and whitened: that covariance's
        eigendecompositions, a dozen of them at every fit, cost the cube of the features
        (at 2,000 features a fit took 49 s, at 10,000 it ran out of time and memory;
        docs/BENCHMARKS.md, "Sensors of many values a touch"). The attribute parts then learn
        from the same components. PHAC-2's 188 features and the simulator's 960 stay whole.
        0 always reduces. A non-negative integer.
    reduce_dims : tuple of int, default (32, 64, 128, 256, 512)
        Where inputs are reduced: the numbers of components tried, the one whose probe (the
        held-out trials below) gives the held-out samples' own classes the highest mean
        log-probability kept (``metrics["reduced_dims"]``). The probe's components are
        learnt without its held-out trials. Each is capped at the features and at one fewer
        than the training samples. Positive integers.
    known_kept : float, default 0.9
        The novelty threshold's operating point: the share of known touches (held-out
        trials of the training objects) it keeps known. In (0, 1).
    distance_weight : float or None, default None
        Weight of the distance cue in the novelty score (0: ``1 - max p`` alone); None
        lets the fit choose it by its probe. Non-negative.
    search_k : int, default 32
        Prototypes each sample is scored against (its nearest). A positive integer.
    exact_below : int, default 4096
        Prototypes searched exactly up to this many; more take an HNSW graph.
    search_dims : int, default 64
        Leading coordinates the HNSW graph is built on. A positive integer.
    calibration_samples : int, default 20000
        Training samples the leave-one-out calibration of ``tau`` and the threshold reads
        (every one where there are fewer). A positive integer.
    shot_margin : float or None, default 20.0
        How much closer a touch must lie to the prototype of a novel class learnt from n
        samples than to its nearest known prototype for the class to keep the probability it
        shares with the other classes with samples: each is scored by the profile
        log-likelihood of an isotropic Gaussian around it (-dims/2 log of the squared
        distance, free of the data's scale), the class's less ``shot_margin / n`` (nats).
        What it gives up goes to the novel classes without samples (described ones), in
        proportion to their zero-shot probability. As ``best``'s ``shot_margin``, on this
        method's own scale; None: no bound, as before 2026-11-28. Of 0 to 80, 20 answered
        the novel objects' touches best (described objects' and one-shot objects' recall
        averaged, on PHAC-2 and the simulator, split seed 20; ``bench.one_shot_swallow``).
        Non-negative, or None.
    attribute_C : float, default 0.1
        As ``best``'s: the L2 penalty's inverse of DAP's attribute classifiers.
    attribute_samples : int, default 50000
        As ``best``'s: the most training samples the attribute parts learn from.
    dap_clip : float, default 0.02
        As ``best``'s: DAP's clip of each attribute probability.
    sae_lambda : float, default 400.0
        As ``best``'s: the semantic autoencoder's regularisation (0: DAP alone).
    sae_temperature : float, default 10.0
        As ``best``'s: the autoencoder's cosine weight in the zero-shot scores.
    n_jobs : int or None, default 1
        Threads of the attribute classifiers (joblib's convention).
    featurizer_params : dict or None, default None
        The raw-trial featurizer's options, as ``best``'s.
    """

    method = "prototypes"
    novel_part_separable = True  # enrolments never touch the space or the known prototypes
    graded_attributes = True
    attributes_separable = True
    learns_known_incrementally = True  # a promoted class is a new prototype
    learns_classes_from_samples = True
    _featurizer_defaults = {"n_offsets": 1}
    #: the principal components the inputs are reduced to (``reduce_above``), or None
    reduction_: BlockPCA | None = None
    #: batches of at most this many complete samples, of a model without a reduction, take
    #: ``PrototypeSmallBatch`` (the general path's answers to rounding, at a fraction of its
    #: per-call cost, which dominates for a few samples); 0 forces the general path
    small_batch_max = 32

    _parameter_constraints = {
        "max_modes": integer(1),
        "split_ratio": number(0, 1),
        "reduce_above": integer(0, "be a non-negative integer (0 = always reduce)"),
        "reduce_dims": Constraint(
            lambda v: (
                not isinstance(v, str | bytes)
                and len(v) > 0
                and all(isinstance(d, int | np.integer) and not isinstance(d, bool) for d in v)
                and min(v) >= 1
            ),
            "be a non-empty sequence of positive integers",
        ),
        "known_kept": number(0, 1),
        "distance_weight": either(
            one_of((None,)),
            number(0, include_low=True, allow_bool=False, finite=True),
            must="be None or a non-negative number",
        ),
        "search_k": integer(1),
        "exact_below": integer(0),
        "search_dims": integer(1),
        "calibration_samples": integer(1),
        "shot_margin": either(
            one_of((None,)),
            number(0, include_low=True, allow_bool=False, finite=True),
            must="be None or a non-negative number",
        ),
        "attribute_C": number(0),
        "attribute_samples": integer(0, "be a non-negative integer (0 = every sample)"),
        "dap_clip": number(0, 0.5),
        "sae_lambda": number(0, include_low=True, allow_bool=False, finite=True),
        "sae_temperature": number(0, include_low=True, allow_bool=False, finite=True),
    }

    def __init__(
        self,
        seed: int = 0,
        max_modes: int = 3,
        split_ratio: float = 0.7,
        reduce_above: int = 1024,
        reduce_dims: tuple[int, ...] = (32, 64, 128, 256, 512),
        known_kept: float = 0.9,
        distance_weight: float | None = None,
        search_k: int = 32,
        exact_below: int = 4096,
        search_dims: int = 64,
        calibration_samples: int = 20000,
        shot_margin: float | None = SHOT_MARGIN,
        attribute_C: float = 0.1,
        attribute_samples: int = 50000,
        dap_clip: float = 0.02,
        sae_lambda: float = 400.0,
        sae_temperature: float = 10.0,
        n_jobs: int | None = 1,
        featurizer_params: dict[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.seed = seed
        self.max_modes = max_modes
        self.split_ratio = split_ratio
        self.reduce_above = reduce_above
        self.reduce_dims = reduce_dims
        self.known_kept = known_kept
        self.distance_weight = distance_weight
        self.search_k = search_k
        self.exact_below = exact_below
        self.search_dims = search_dims
        self.calibration_samples = calibration_samples
        self.shot_margin = shot_margin
        self.attribute_C = attribute_C
        self.attribute_samples = attribute_samples
        self.dap_clip = dap_clip
        self.sae_lambda = sae_lambda
        self.sae_temperature = sae_temperature
        self.n_jobs = n_jobs
        self.featurizer_params = featurizer_params

    # ----------------------------------------------------------------- fitting
    def _fit(self, dataset: TactileDataset, progress: bool) -> None:
        from app.framework.novelty import threshold_at_kept

        check_known_classes(dataset, "prototypes")
        t0 = time.perf_counter()
        timings: dict[str, float] = {}
        x = flatten(dataset.samples)
        y = np.asarray(dataset.labels, np.int64)
        # medians and quartiles from a sample of rows: a float64 copy of every row and
        # np.percentile's own copies took gigabytes at 30,000 objects
        rng = np.random.default_rng(int(self.seed))
        some = np.sort(rng.choice(len(x), min(len(x), _SCALER_SAMPLES), replace=False))
        self.scaler_ = RobustInputScaler().fit(x[some])
        z = self.scaler_.transform(x)
        del x
        k = dataset.n_classes
        bar = tqdm(
            total=2,
            desc=f"prototypes on {dataset.name}: probe, model",
            disable=bar_disabled(progress),
        )
        probe = self._probe(z, y, np.asarray(dataset.trials), k)
        if probe is None:
            raise DatasetError(
                "calibration needs held-out trials: give at least 2 known classes 2 trials"
            )
        self.tau_ = probe["tau"]
        self.distance_weight_ = probe["distance_weight"]
        self.novelty_tuning = threshold_at_kept(
            probe["known_scores"], probe["novel_scores"], float(self.known_kept)
        )
        self.novelty_threshold = float(self.novelty_tuning.threshold)
        self.reduction_ = None
        if probe["reduced_dims"] is not None:
            self.reduction_ = self._reduction(probe["reduced_dims"]).fit(z)
            z = self.reduction_.transform(z)
        timings["probe_s"] = time.perf_counter() - t0
        bar.update()

        t = time.perf_counter()
        embedding = self._embedding(probe["modes"]).fit(z, y, k)
        # the probe saw one trial a class fewer: its shrinkage, scaled as Ledoit-Wolf's own
        # estimate moves from the probe's samples to all of them (on the simulator at 300
        # objects the probe's 0.9 was 0.7 with all trials, 0.918 against 0.950 accuracy);
        # unscaled where either is 0 (classes of one trial have no spread)
        shrink = probe["shrinkage"]
        if probe["ledoit_wolf"] > 0 and embedding.ledoit_wolf_ > 0:
            shrink *= embedding.ledoit_wolf_ / probe["ledoit_wolf"]
        self.embedding_ = embedding.shrunk(float(np.clip(shrink, 0.0, 1.0))).release()
        owner = embedding.subclass_class_
        self._set_prototypes(
            owner, np.bincount(embedding.subclass_, minlength=len(owner)).astype(np.float64)
        )
        points = self.embedding_.transform(embedding.subclass_means_)
        self.search_ = PrototypeSearch(points, int(self.exact_below), int(self.search_dims))
        timings["embedding_s"] = time.perf_counter() - t
        t = time.perf_counter()
        self.novelty_tuning.touches = self._touch_curves(
            z, y, np.asarray(dataset.trials), embedding.subclass_, points
        )
        del embedding, points
        timings["touch_curves_s"] = time.perf_counter() - t
        bar.update()
        bar.close()

        t = time.perf_counter()
        self._fit_attributes(z, y)
        timings["attributes_s"] = time.perf_counter() - t
        self._marginals: dict[tuple[int, ...], tuple] = {}
        self._reset_novel()
        rows = np.random.default_rng(int(self.seed)).permutation(len(z))
        self.procedure_order_ = self._procedure_order(z, y, rows[: int(self.calibration_samples)])
        timings["total_s"] = time.perf_counter() - t0
        self.metrics = {
            "n_train_samples": int(len(dataset)),
            "n_known_classes": int(k),
            "n_prototypes": int(len(self.proto_class_)),
            "shrinkage": float(self.embedding_.shrinkage_),
            "tau": float(self.tau_),
            "distance_weight": float(self.distance_weight_),
            "probe_known_acc": probe["accuracy"],
            "reduced_dims": probe["reduced_dims"],
            "reduction_ll": probe["reduction_ll"],
            "modes": probe["modes"],
            "nd_known_kept": self.novelty_tuning.known_kept_at_threshold,
            "nd_val_novel": self.novelty_tuning.val_novel_at_threshold,
            "nd_val_auroc": self.novelty_tuning.auroc,
            "exact_search": bool(self.search_.exact),
            "timings": timings,
            "params": self.get_params(),
        }

    def _touch_curves(
        self,
        z: np.ndarray,
        y: np.ndarray,
        trials: np.ndarray,
        subclass: np.ndarray,
        points: np.ndarray,
    ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """The calibration curves of answers fusing k touches of one known object
        (``app.framework.novelty.touch_curves``), from leave-one-trial-out novelty scores of
        the training touches in the fitted space: each touch scored against the prototypes
        with its own trial's samples taken out of them (a mean less those samples, one
        subtraction), as a new touch of a known object meets the deployed model. Read from
        the whole trials of classes drawn at random, up to ``calibration_samples`` rows.
        ``subclass``: each training row's prototype; ``points``: the prototypes' coordinates.

        The threshold's own probe holds out one trial a class, too few to fuse: an answer
        fusing three touches read the single touches' curve and kept more known than it
        stated. Scored in the space fitted on every trial, a touch sits closer to its class
        than a held-out one (PHAC-2, 6 development splits: 0.74 kept at 2 touches for 0.90
        stated): each curve is mapped, through the share of single touches it keeps here,
        onto the probe's curve of held-out touches."""
        from app.framework.novelty import touch_curves

        rows = _whole_trials(y, trials, int(self.calibration_samples), int(self.seed))
        if rows is None:
            return {}
        e = self.embedding_.transform(z[rows])
        yr, tr, sub = y[rows], trials[rows], subclass[rows]
        # each (prototype, trial)'s samples among the rows: every trial of a drawn class is
        # there whole, so these are all of the trial's samples in that prototype
        groups, group_of = np.unique(np.stack([sub, tr], axis=1), axis=0, return_inverse=True)
        group_of = group_of.ravel()
        group_n = np.bincount(group_of).astype(np.float64)
        group_sum = np.zeros((len(groups), e.shape[1]))
        np.add.at(group_sum, group_of, e)
        trial_n = np.unique(np.stack([yr, tr], axis=1), axis=0, return_inverse=True)[1].ravel()
        trial_n = np.bincount(trial_n)[trial_n].astype(np.float64)

        ids, dist = self.search_.nearest(e, int(self.search_k))
        dist = dist.astype(np.float64)
        count = self.proto_count_[ids].copy()
        cls = self.proto_class_[ids]
        class_n = self.class_n_[cls] - np.where(cls == yr[:, None], trial_n[:, None], 0.0)
        # candidates holding samples of the row's own trial: their means without them
        key = groups[:, 0] * (int(tr.max()) + 1) + groups[:, 1]
        wanted = ids * (int(tr.max()) + 1) + tr[:, None]
        at = np.minimum(np.searchsorted(key, wanted), len(key) - 1)
        i, j = np.nonzero((key[at] == wanted) & (ids >= 0))
        g = at[i, j]
        left = count[i, j] - group_n[g]
        mean = points[ids[i, j]] * count[i, j][:, None] - group_sum[g]
        mean /= np.maximum(left, 1.0)[:, None]
        count[i, j] = left
        dist[i, j] = np.where(left > 0, ((e[i] - mean) ** 2).sum(axis=1), dist[i, j])
        gone = count <= 0
        count = np.where(gone, 1.0, count)
        class_n = np.maximum(class_n, 1.0)
        dims = e.shape[1]
        logp = class_log_posterior(dist, count, class_n, cls, self.tau_, dims, gone)
        score = novelty_scores(logp, dist, count, self.tau_, dims, self.distance_weight_, gone)
        # these scores sit lower than held-out ones (the space was fitted on every trial):
        # each curve's thresholds are mapped through the share of single touches they keep
        # here onto the probe's curve, the threshold keeping that share of held-out touches
        single = np.sort(score)
        probe = self.novelty_tuning

        def held_out(thresholds: np.ndarray) -> np.ndarray:
            share = np.searchsorted(single, thresholds, side="right") / len(single)
            return np.interp(share, probe.known_kept, probe.thresholds)

        return {k: (held_out(t), q) for k, (t, q) in touch_curves(score, np.c_[yr, tr]).items()}

    def _embedding(self, modes: int | None = None) -> SubclassEmbedding:
        modes = int(self.max_modes) if modes is None else modes
        return SubclassEmbedding(modes, float(self.split_ratio), seed=int(self.seed))

    def _probe(
        self, z: np.ndarray, y: np.ndarray, trials: np.ndarray, k: int
    ) -> dict[str, Any] | None:
        """A probe fitted without one whole trial of each class that has two or more, scoring
        them: the shrinkage (Ledoit-Wolf's or one of ``_SHRINKAGES``) and ``tau`` whose
        posterior gives the held-out samples' own classes the highest mean log-probability,
        and the novelty scores of the held-out samples with their class's prototypes (known)
        and without (pseudo-novel)."""
        held = _held_out_trials(y, trials, np.random.default_rng(int(self.seed)))
        if held.sum() == 0 or len(np.unique(y[held])) < 2:
            return None
        fit = ~held
        rows = np.flatnonzero(held)
        if len(rows) > int(self.calibration_samples):
            rng = np.random.default_rng(int(self.seed) + 1)
            rows = np.sort(rng.choice(rows, int(self.calibration_samples), replace=False))
        yh = y[rows]
        space: dict[str, Any] = {}
        tried: dict[str, float] = {}
        for n_dims, zr in self._probe_inputs(z, fit):
            # reduced, classes are also tried whole: with 3 trials a class in the probe, a
            # class split into modes of one trial each leaves no within-class spread to
            # whiten by (60 objects of 4 trials, 10,000 values a touch: the held-out trials'
            # mean log-probability -12.5 with 3 modes, -0.29 whole)
            every = (int(self.max_modes),) if n_dims is None else sorted({1, int(self.max_modes)})
            for modes in every:
                got = self._probe_space(zr[fit], y[fit], zr[rows], yh, k, modes)
                if n_dims is not None:
                    tried[f"{n_dims}/{modes}"] = got["best"]["ll"]
                if not space or got["best"]["ll"] > space["best"]["ll"] + 1e-9:
                    space = {**got, "reduced_dims": n_dims, "modes": modes}
        best, base, dims = space["best"], space["base"], space["dims"]
        owner, count_all, class_total = space["owner"], space["count_all"], space["class_total"]
        dist, ids, tau = best["dist"], best["ids"], best["tau"]
        cls, count = owner[ids], count_all[ids]
        class_n = class_total[cls]
        mine = cls == yh[:, None]
        from sklearn.metrics import roc_auc_score

        logp = class_log_posterior(dist, count, class_n, cls, tau, dims)
        logp_n = class_log_posterior(dist, count, class_n, cls, tau, dims, mine)
        alone = mine.all(axis=1)  # no other class among the candidates: nothing to score
        weights = DISTANCE_WEIGHTS if self.distance_weight is None else (self.distance_weight,)
        chosen: dict[str, Any] = {"auroc": -1.0}
        for w in weights:
            known = novelty_scores(logp, dist, count, tau, dims, float(w))
            novel = novelty_scores(logp_n, dist, count, tau, dims, float(w), mine)[~alone]
            truth = np.r_[np.zeros(len(known)), np.ones(len(novel))]
            auroc = float(roc_auc_score(truth, np.r_[known, novel])) if len(novel) else 0.0
            if auroc > chosen["auroc"] + 1e-9:
                chosen = {"auroc": auroc, "weight": float(w), "known": known, "novel": novel}
        return {
            "reduced_dims": space["reduced_dims"],
            "modes": space["modes"],
            "reduction_ll": tried,
            "shrinkage": best["shrinkage"],
            "ledoit_wolf": base.ledoit_wolf_,
            "tau": tau,
            "distance_weight": chosen["weight"],
            "accuracy": best["accuracy"],
            "known_scores": chosen["known"],
            "novel_scores": chosen["novel"],
        }

    def _probe_space(
        self, zf: np.ndarray, yf: np.ndarray, zh: np.ndarray, yh: np.ndarray, k: int, modes: int
    ) -> dict[str, Any]:
        """The probe's space, fitted on ``zf`` (classes ``yf``) with at most ``modes``
        subclasses a class, and its shrinkage and ``tau`` that give the held-out ``zh`` their
        classes ``yh`` the highest mean log-probability (``best["ll"]``, a class posterior:
        comparable between spaces)."""
        base = self._embedding(modes).fit(zf, yf, k)
        owner = base.subclass_class_
        count_all = np.bincount(base.subclass_, minlength=len(owner)).astype(np.float64)
        class_total = _class_totals(owner, count_all, k)
        k_search = int(self.search_k) + int(self.max_modes)
        dims = zf.shape[1]
        best: dict[str, Any] = {"ll": -np.inf}
        for shrink in (base.ledoit_wolf_, *_SHRINKAGES):
            emb = base.shrunk(shrink)
            search = PrototypeSearch(
                emb.transform(base.subclass_means_), int(self.exact_below), int(self.search_dims)
            )
            ids, dist = search.nearest(emb.transform(zh), k_search)
            cls, count = owner[ids], count_all[ids]
            mine = cls == yh[:, None]
            for tau in _TAUS:
                logp = class_log_posterior(dist, count, class_total[cls], cls, tau, dims)
                ll = float(np.maximum(np.where(mine, logp, -np.inf).max(axis=1), -50.0).mean())
                if ll > best["ll"] + 1e-9:
                    best = {"ll": ll, "shrinkage": float(shrink), "tau": float(tau), "ids": ids}
                    best["dist"], best["accuracy"] = dist, float((cls[:, 0] == yh).mean())
        return {
            "best": best,
            "base": base,
            "dims": dims,
            "owner": owner,
            "count_all": count_all,
            "class_total": class_total,
        }

    def _reduces(self, n_features: int) -> bool:
        return n_features > int(self.reduce_above)

    def _reduction(self, n_components: int) -> BlockPCA:
        blocks = max(len(self.procedures), 1)
        return BlockPCA(int(n_components), blocks, int(self.seed), _SCALER_SAMPLES)

    def _probe_inputs(self, z: np.ndarray, fit: np.ndarray):
        """(components kept or None, inputs) for each space the probe tries: the scaled
        inputs themselves, or, where they are reduced, their leading components for each of
        ``reduce_dims`` (distinct after the caps), learnt from the probe's rows ``fit``."""
        if not self._reduces(z.shape[1]):
            yield None, z
            return
        whole = self._reduction(max(int(d) for d in self.reduce_dims)).fit(z[fit])
        seen: set[int] = set()
        for d in sorted(int(d) for d in self.reduce_dims):
            part = whole.truncated(d)
            if part.n_features_out not in seen:
                seen.add(part.n_features_out)
                yield part.n_features_out, part.transform(z)

    def _scaled(self, x: np.ndarray) -> np.ndarray:
        """Flat inputs scaled, and reduced where the fit reduced them."""
        z = self.scaler_.transform(x)
        return z if self.reduction_ is None else self.reduction_.transform(z)

    def _procedure_order(self, z: np.ndarray, y: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Procedures by known accuracy alone per robot second (on the calibration samples,
        their own trial still in the prototypes), best first; empty for one procedure."""
        if len(self.procedures) < 2:
            return np.zeros(0, np.int64)
        rows = rows[:_ORDER_SAMPLES]
        gains = []
        for j in range(len(self.procedures)):
            right = 0
            for lo in range(0, len(rows), _BLOCK):
                block = rows[lo : lo + _BLOCK]
                p = self._marginal_scores(z[block], (j,))[0]
                right += int((p.argmax(axis=1) == y[block]).sum())
            gains.append(right / len(rows))
        per_second = np.asarray(gains) / seconds_of(self.procedures)
        return np.argsort(-per_second, kind="stable")

    def _refit_attributes(self, dataset: TactileDataset) -> None:
        self._fit_attributes(self._scaled(flatten(dataset.samples)), dataset.labels)
        self.metrics = {**self.metrics, "n_attributes": len(self.registry.attribute_names)}

    # --------------------------------------------------------------- scoring
    def _candidates(self, e: np.ndarray) -> tuple[np.ndarray, ...]:
        ids, dist = self.search_.nearest(e, int(self.search_k))
        cls = self.proto_class_[ids]
        count = self.proto_count_[ids]
        return ids, dist, cls, count, self.class_n_[cls]

    def _scores_e(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(known probabilities (N, K), novelty scores (N,)) of embedded samples."""
        _, dist, cls, count, class_n = self._candidates(e)
        dims = e.shape[1]
        logp = class_log_posterior(dist, count, class_n, cls, self.tau_, dims)
        known = _dense(np.exp(logp), cls, len(self.registry.known_names))
        weight = self.distance_weight_
        return known, novelty_scores(logp, dist, count, self.tau_, dims, weight)

    def _embedded(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = self._scaled(flatten(samples))
        return z, self.embedding_.transform(z)

    def _known_proba(self, samples: np.ndarray) -> np.ndarray:
        return self._scores_e(self._embedded(samples)[1])[0]

    def _novelty_score(self, samples: np.ndarray) -> np.ndarray:
        return self._scores_e(self._embedded(samples)[1])[1]

    def _novel_proba(self, samples: np.ndarray) -> np.ndarray:
        z, e = self._embedded(samples)
        return self._novel_from(z, e)

    def _all_scores(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        if len(samples) <= self.small_batch_max and self.reduction_ is None:
            few = getattr(self, "_few", None)
            if few is None or not few.fits(self):
                few = self._few = PrototypeSmallBatch(self)
            novelty, known, e, z, near = few.scores(flatten(samples))
            novel = None
            if self.registry.novel_names:
                zsl = few.zero_shot(self, z) if self.has_attributes else None
                novel = self._novel_from(z, e, near=near, p_zsl=zsl)
            return novelty, known, novel
        z, e = self._embedded(samples)
        known, novelty = self._scores_e(e)
        novel = self._novel_from(z, e) if self.registry.novel_names else None
        return novelty, known, novel

    def _novel_from(
        self,
        z: np.ndarray,
        e: np.ndarray,
        shot_points: np.ndarray | None = None,
        search: PrototypeSearch | None = None,
        near: tuple[np.ndarray, np.ndarray] | None = None,
        p_zsl: np.ndarray | None = None,
    ) -> np.ndarray:
        """The novel classes' probabilities from scaled inputs ``z`` and their coordinates
        ``e``, in which the one-shot prototypes are ``shot_points`` and the known ones are
        searched by ``search`` (the fitted space's, ``shot_points_`` and ``search_``, unless
        given: a marginal's). ``near``: the ``search_k`` nearest known prototypes' (ids,
        squared distances) where the caller found them already (the fitted space's);
        ``p_zsl``: the zero-shot posterior, where computed already."""
        reg = self.registry
        has = self.shot_has_
        if p_zsl is None and self.has_attributes:
            p_zsl = self._zero_shot(z)
        elif p_zsl is None:
            p_zsl = np.zeros((len(z), len(reg.novel_names)))
        if not has.any():
            return p_zsl
        points = self.shot_points_ if shot_points is None else shot_points
        shot_dist = self._shot_distances(e, points[has])  # the density's and the bound's
        logd = self._shot_log_density(e, points[has], self.shot_counts_[has], shot_dist)
        p_shot = softmax(logd)
        out = p_zsl.copy()
        rest = 1.0 - p_zsl[:, ~has].sum(axis=1, keepdims=True) if self.has_attributes else 1.0
        out[:, has] = rest * p_shot
        if self.shot_margin is None or not self.has_attributes or has.all():
            return out
        # the bound (one_shot.bounded_shots), the known prototypes the rivals: each scores
        # the touch by the profile log-likelihood of an isotropic Gaussian around it whose
        # spread, fitted to the touch, is that prototype's share (1 + 1/n) of a common one:
        # -dims/2 log(squared distance / (1 + 1/n)), free of the data's scale. A mean of n
        # samples lies farther from its object's touches the fewer they are (a single
        # sample, twice as far squared), and tau's Gaussian, with its normaliser, vetoed or
        # favoured the class by the dataset's scale (on the simulator, all its own touches)
        half = 0.5 * e.shape[1]
        if near is None:
            near = (self.search_ if search is None else search).nearest(e, int(self.search_k))
        ids, dist = near
        spread = dist.astype(np.float64) / (1.0 + 1.0 / self.proto_count_[ids])
        rival = -half * np.log(np.maximum(spread.min(axis=1), _TINY))
        counts = self.shot_counts_[has]
        shot_spread = shot_dist / (1.0 + 1.0 / counts)
        shot = -half * np.log(np.maximum(shot_spread, _TINY))
        shot -= shot_penalty(self.shot_margin, counts)
        return bounded_shots(out, has, shot, rival)

    def _shot_log_density(
        self,
        e: np.ndarray,
        points: np.ndarray,
        counts: np.ndarray,
        dist: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N, S) log density of each touch under each class with samples' Gaussian (the
        known part's, variance ``tau (1 + 1/n)``); its softmax shares their probability.
        ``dist``: the touches' ``_shot_distances`` to ``points`` where computed already."""
        if dist is None:
            dist = self._shot_distances(e, points)
        v = 1.0 + 1.0 / counts
        return -dist / (2.0 * self.tau_ * v) - 0.5 * e.shape[1] * np.log(v)

    @staticmethod
    def _shot_distances(e: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(N, S) squared distances from the touches ``e`` to the one-shot prototypes."""
        e64, p64 = e.astype(np.float64), points.astype(np.float64)
        dist = (e64**2).sum(axis=1)[:, None] - 2.0 * e64 @ p64.T + (p64**2).sum(axis=1)
        return np.maximum(dist, 0.0)

    def _attribute_proba(self, samples: np.ndarray) -> np.ndarray:
        return self.attributes_.predict_proba(self._scaled(flatten(samples)))

    def __getstate__(self) -> dict[str, Any]:
        # the marginal models are a cache of this model: a copy (each enrolment's) builds its
        # own on first use rather than copying prototypes for every set of procedures
        return {**self.__dict__, "_marginals": {}, "_few": None}

    # --------------------------------------------------------------- enrolment
    def _set_prototypes(self, owner: np.ndarray, counts: np.ndarray) -> None:
        """Each prototype's class and sample count, and each class's samples (``class_n_``,
        read by every answer: kept, not summed again per call)."""
        self.proto_class_ = np.asarray(owner, np.int64)
        self.proto_count_ = np.asarray(counts, np.float64)
        self.class_n_ = _class_totals(
            self.proto_class_, self.proto_count_, len(self.registry.known_names)
        )

    def _grow_known(self, samples: np.ndarray, labels: np.ndarray) -> None:
        """Each class's new samples become one prototype of their own, beside the index; the
        space, ``tau`` and the threshold stay as fitted, and the attribute parts never see a
        promoted class's samples until the next full fit."""
        e = self.embedding_.transform(self._scaled(flatten(samples)))
        classes = np.unique(labels)
        points = np.stack([e[labels == c].mean(axis=0) for c in classes])
        counts = np.array([(labels == c).sum() for c in classes], np.float64)
        self.search_ = self.search_.with_points(points)
        self._set_prototypes(
            np.concatenate([self.proto_class_, classes]),
            np.concatenate([self.proto_count_, counts]),
        )
        grown = int(self.metrics.get("n_grown_samples", 0))
        self.metrics = {
            **self.metrics,
            "n_known_classes": len(self.registry.known_names),
            "n_grown_samples": grown + len(samples),
        }
        self._marginals = {}

    def _reset_novel(self) -> None:
        d = self.search_.points.shape[1]
        self.shot_points_ = np.zeros((0, d), np.float32)
        self.shot_counts_ = np.zeros(0, np.float64)
        self.shot_has_ = np.zeros(0, bool)

    def _refit_novel(self, **options: Any) -> None:
        if options:
            raise FrameworkError(
                f"method '{self.method}' takes no enrolment options, got {sorted(options)}"
            )
        reg = self.registry
        d = self.search_.points.shape[1]
        points = np.zeros((len(reg.novel_names), d), np.float32)
        counts = np.ones(len(reg.novel_names), np.float64)
        has = np.zeros(len(reg.novel_names), bool)
        for i, name in enumerate(reg.novel_names):
            samples = reg.novel_samples.get(name)
            if samples is not None and len(samples):
                points[i] = self._embedded(samples)[1].mean(axis=0)
                counts[i], has[i] = len(samples), True
        self.shot_points_, self.shot_counts_, self.shot_has_ = points, counts, has

    # ------------------------------------------------------- missing procedures
    @property
    def answers_from_some_procedures(self) -> bool:
        return len(self.procedures) >= 2

    @property
    def first_procedure(self) -> str | None:
        if not self.answers_from_some_procedures:
            return None
        return self.procedures[int(self.procedure_order_[0])]

    def _features(self, keep: tuple[int, ...]) -> np.ndarray:
        if self.reduction_ is not None:  # each procedure's components, block after block
            width = self.reduction_.components_.shape[1]
            return np.concatenate([np.arange(j * width, (j + 1) * width) for j in keep])
        cols = np.zeros(self.input_shape, bool)
        for j in keep:
            cols[block(self.procedures, self.input_shape, j)] = True
        return np.flatnonzero(cols.ravel())

    def _marginal(self, keep: tuple[int, ...]) -> tuple:
        """(features, the others, centre, projection, the prototypes' exact search, the map
        from the full space's coordinates, imputation) of the marginal model on procedures
        ``keep``, built on first use and kept."""
        got = self._marginals.get(keep)
        if got is None:
            feats = self._features(keep)
            center, proj = self.embedding_.marginal(feats)
            # prototypes in the scaled inputs' space: centre + point @ inverse projection
            inverse = np.linalg.pinv(self.embedding_.projection_.astype(np.float64))
            mapping = (inverse[:, feats] @ proj).astype(np.float32)
            protos = np.concatenate([self.search_.points, self.search_.extra]) @ mapping
            # exact: the marginal's coordinates are not ordered for a graph over the leading ones
            search = PrototypeSearch(protos, exact_below=len(protos))
            cov = self.embedding_.covariance_.astype(np.float64)
            rest = np.setdiff1d(np.arange(cov.shape[0]), feats)
            impute_m = np.linalg.solve(
                cov[np.ix_(feats, feats)] + 1e-6 * np.eye(len(feats)), cov[np.ix_(feats, rest)]
            ).astype(np.float32)
            got = (feats, rest, center, proj, search, mapping, impute_m)
            self._marginals[keep] = got
        return got

    def _marginal_scores(
        self, z: np.ndarray, keep: tuple[int, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(known probabilities, novelty scores, embedded rows) from procedures ``keep``."""
        feats, _, center, proj, search, _, _ = self._marginal(keep)
        e = (z[:, feats] - center) @ proj
        near, dist = search.nearest(e, int(self.search_k))
        cls, count = self.proto_class_[near], self.proto_count_[near]
        dims = e.shape[1]
        logp = class_log_posterior(dist, count, self.class_n_[cls], cls, self.tau_, dims)
        known = _dense(np.exp(logp), cls, len(self.registry.known_names))
        weight = self.distance_weight_
        return known, novelty_scores(logp, dist, count, self.tau_, dims, weight), e

    def _imputed(self, x: np.ndarray, keep: tuple[int, ...]) -> np.ndarray:
        """Scaled inputs with the missing features at their conditional mean given the rest."""
        feats, rest, *_, impute_m = self._marginal(keep)
        z = self._scaled(np.nan_to_num(flatten(x)))
        mean = self.embedding_.center_
        z[:, rest] = mean[rest] + (z[:, feats] - mean[feats]) @ impute_m
        return z

    def _subset_scores(
        self, x: np.ndarray, keep: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        keep = tuple(int(j) for j in keep)
        z = self._imputed(x, keep)
        known, novelty, e = self._marginal_scores(z, keep)
        novel = None
        if self.registry.novel_names:
            marginal = self._marginal(keep)
            novel = self._novel_from(z, e, self.shot_points_ @ marginal[5], marginal[4])
        return novelty, known, novel

    def _subset_attribute_proba(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        return self.attributes_.predict_proba(self._imputed(x, tuple(int(j) for j in keep)))

    def _next_procedures(
        self, known_p: np.ndarray, used: np.ndarray, ask: np.ndarray
    ) -> np.ndarray:
        out = np.full(len(known_p), -1, np.int64)
        for i in np.flatnonzero(ask):
            left = [j for j in self.procedure_order_ if not used[i, j]]
            if left:
                out[i] = int(left[0])
        return out

    # ------------------------------------------------------------ persistence
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        arrays: dict[str, np.ndarray] = {
            "prior": self.prior_,
            "points": np.concatenate([self.search_.points, self.search_.extra]),
            "n_fitted_points": np.asarray(len(self.search_.points), np.int64),
            "index": self.search_.index_bytes(),
            "proto_class": self.proto_class_,
            "proto_count": self.proto_count_,
            "procedure_order": np.asarray(self.procedure_order_, np.int64),
        }
        if self.sae_ is not None:
            arrays["sae"] = self.sae_
        for key, value in self.scaler_.get_state().items():
            arrays[f"scaler/{key}"] = value
        for key, value in self.embedding_.get_state().items():
            arrays[f"embedding/{key}"] = value
        if self.reduction_ is not None:
            for key, value in self.reduction_.get_state().items():
                arrays[f"reduction/{key}"] = value
        for key, value in self.attributes_.get_state().items():
            arrays[f"attributes/{key}"] = value
        meta = {
            "params": self.get_params(),
            "tau": float(self.tau_),
            "distance_weight": float(self.distance_weight_),
        }
        return meta, arrays

    def set_state(self, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ensure_threads_configured()
        names = self._get_param_names()
        for key, value in meta["params"].items():
            if key not in names:
                raise KeyError(f"unknown parameter {key!r} in the bundle")
            setattr(self, key, value)
        self._validate_params()

        def part(prefix: str) -> dict[str, np.ndarray]:
            return {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)}

        self.scaler_ = RobustInputScaler()
        self.scaler_.set_state(part("scaler/"))
        self.embedding_ = SubclassEmbedding.from_state(part("embedding/"))
        reduction = part("reduction/")
        self.reduction_ = BlockPCA.from_state(reduction) if reduction else None
        n_features = int(np.prod(self.input_shape))
        inner = n_features
        if self.reduction_ is not None:
            if self.reduction_.n_features_in != n_features:
                raise ValueError(
                    f"the reduction expects {self.reduction_.n_features_in} features, "
                    f"inputs have {n_features}"
                )
            inner = self.reduction_.n_features_out
        if self.embedding_.projection_.shape[0] != inner:
            raise ValueError(
                f"the embedding expects {self.embedding_.projection_.shape[0]} features, "
                f"inputs have {inner}"
            )
        points = np.asarray(arrays["points"], np.float32)
        fitted = int(arrays["n_fitted_points"])
        self.search_ = PrototypeSearch(points[:fitted], index=arrays["index"])
        if fitted < len(points):
            self.search_ = self.search_.with_points(points[fitted:])
        self._set_prototypes(arrays["proto_class"], arrays["proto_count"])
        if len(self.proto_class_) != len(points) or (
            len(points) and self.proto_class_.max() >= len(self.registry.known_names)
        ):
            raise ValueError("the prototypes do not match the bundle's known classes")
        self.procedure_order_ = np.asarray(arrays["procedure_order"], np.int64)
        self.tau_ = float(meta["tau"])
        self.distance_weight_ = float(meta["distance_weight"])
        self.attributes_ = LinearAttributeModel.from_state(part("attributes/"))
        self.prior_ = np.asarray(arrays["prior"], np.float64)
        self.sae_ = np.asarray(arrays["sae"], np.float32) if "sae" in arrays else None
        self._marginals = {}
        self._reset_novel()
        if self.registry.novel_names:
            self._refit_novel()


def class_log_posterior(
    dist: np.ndarray,
    count: np.ndarray,
    class_n: np.ndarray,
    cls: np.ndarray,
    tau: float,
    dims: int,
    gone: np.ndarray | None = None,
) -> np.ndarray:
    """(N, k) log posterior of each candidate prototype's class, given the squared distances
    ``dist`` to the candidates, their sample counts, their classes' sample counts and their
    classes ``cls``: each prototype an isotropic Gaussian of variance ``tau (1 + 1/count)``
    in ``dims`` coordinates weighted by its share of its class; every candidate of a class
    carries the class's summed value. Candidates marked ``gone`` count for nothing."""
    v = 1.0 + 1.0 / count
    logd = -dist / (2.0 * tau * v) - 0.5 * dims * np.log(v) + np.log(count / class_n)
    if gone is not None:
        logd = np.where(gone, -np.inf, logd)
    top = logd.max(axis=1, keepdims=True)
    w = np.exp(logd - np.where(np.isfinite(top), top, 0.0))
    same = cls[:, :, None] == cls[:, None, :]
    class_w = (w[:, None, :] * same).sum(axis=2)
    total = np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    return np.log(np.maximum(class_w, 1e-300)) - np.log(total)


def novelty_scores(
    logp: np.ndarray,
    dist: np.ndarray,
    count: np.ndarray,
    tau: float,
    dims: int,
    weight: float,
    gone: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) novelty: ``1 - max p`` plus ``weight`` x the log squared distance to the nearest
    candidate, per coordinate and in units of its variance (100: nearly the distance alone)."""
    per = dist / (1.0 + 1.0 / count)
    if gone is not None:
        per = np.where(gone, np.inf, per)
    log_d = np.log(per.min(axis=1) / (dims * tau) + 1e-12)
    return 1.0 - np.exp(logp.max(axis=1)) + (weight * log_d if weight else 0.0)


def _held_out_trials(y: np.ndarray, trials: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) bool: one whole trial, drawn at random, of each class that has two or more."""
    pairs = np.unique(np.stack([y, trials], axis=1), axis=0)  # sorted by class, then trial
    classes, first, n_trials = np.unique(pairs[:, 0], return_index=True, return_counts=True)
    chosen = np.full(int(y.max()) + 1, -1, pairs.dtype)
    pick = first + (rng.random(len(classes)) * n_trials).astype(np.int64)
    chosen[classes] = np.where(n_trials >= 2, pairs[pick, 1], -1)
    return (chosen[y] == trials) & (chosen[y] != -1)


def _whole_trials(y: np.ndarray, trials: np.ndarray, most: int, seed: int) -> np.ndarray | None:
    """Sorted rows of whole classes with two or more trials, classes drawn at random until
    ``most`` rows (at least one class); None where no class has two trials."""
    pairs = np.unique(np.stack([y, trials], axis=1), axis=0)
    classes, n_trials = np.unique(pairs[:, 0], return_counts=True)
    classes = classes[n_trials >= 2]
    if len(classes) == 0:
        return None
    rows_of = np.bincount(y, minlength=int(y.max()) + 1)
    order = np.random.default_rng(seed).permutation(classes)
    taken = order[: max(1, int(np.searchsorted(np.cumsum(rows_of[order]), most, "right")))]
    return np.flatnonzero(np.isin(y, taken))


def _class_totals(owner: np.ndarray, counts: np.ndarray, n: int | None = None) -> np.ndarray:
    return np.bincount(owner, weights=counts, minlength=n or 0)


def _dense(p: np.ndarray, cls: np.ndarray, n_classes: int) -> np.ndarray:
    """(N, K) probabilities from each row's candidates' class values (a class's candidates
    all carry its value: it is set, not added)."""
    out = np.zeros((len(p), n_classes))
    rows = np.repeat(np.arange(len(p)), cls.shape[1])
    out[rows, cls.ravel()] = p.ravel()
    return out
