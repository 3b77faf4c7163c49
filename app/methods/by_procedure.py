"""Answers from some procedures, and which procedure to do next, for the ``best`` method.

A robot that stops exploring once it is sure saves most of its time (PHAC-2: squeeze
alone recognises 0.95 of the known objects). ``ProcedureModels`` holds one ``best``
model per exploratory procedure, fitted on that procedure's block of the samples
(``TactileDataset.procedure_view``) with the same hyper-parameters and the same classes.
A sample that holds the procedures S (not all of them) is answered by the models of S,
their evidence fused as ``recognize_batch`` fuses touches of one object
(``FUSION_RULE``): the mean of their known-class and novel-class probabilities, and of
their novelty scores, each taken relative to its own model's threshold (the fused score
is ``threshold + mean_j(score_j - threshold_j)``, so that one threshold routes it). A
complete sample is answered by the whole model as before. Describing (attribute
probabilities) fuses the same way.

**Next procedure.** For an answer not yet confident, the procedure j not yet done whose
expected gain is largest: with ``p`` the fused known-class probabilities after the
procedures S and c one of the ``candidates`` most probable known classes (weights w_c,
``p`` renormalised over them), the model of j is asked what it would answer for a typical
touch of c (the mean of c's training samples on j's block, ``q_c``); fused with ``p``
(the mean rule, weight |S| : 1) that gives the probability left on c. The gain of j is the
expected rise of the probability on the true class, ``sum_c w_c (fused_c[c] - p[c])``,
and the procedure chosen has the largest gain per second of robot time
(``app.data.procedures.seconds_of``). On PHAC-2's development splits (seeds 1-2, 10
splits, target 0.5, two procedures at least, squeeze first;
``bench/research/explore_stopping.py --first SQUEEZE_SET_PRESSURE_SLOW``) the
gain alone used 0.66 of the robot time, the gain per second 0.54, with known-object
accuracy alike (-0.001 and -0.003 from all procedures) and ``gzsl_h`` -0.026 and +0.005.
Class means are kept per known class (K x D, one pass over the training samples); novel
classes have no training samples and are not candidates, so for a sample routed as novel
the procedures are chosen by what tells its nearest known classes apart.

**First procedure.** Before any touch, the procedure whose model answers the typical
touch of each known class (its mean) with the most probability on that class above
chance, per second of robot time.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

from app.data.dataset import TactileDataset
from app.data.procedures import block, seconds_of

#: known classes weighed by the next-procedure rule (the answer's most probable ones)
CANDIDATES = 5
_ROWS = 2048  # class means scored at a time for the first procedure (K x K at most this tall)


class ProcedureModels:
    """The per-procedure models of a fitted ``best`` model; see the module docstring.

    ``models[j]`` answers from procedure j's block of a sample (``input_shape`` of the
    parent split into ``len(procedures)`` blocks); ``class_means`` is (K, *input_shape),
    the mean training sample of each known class, and ``class_counts`` (K,) their sizes.
    """

    def __init__(
        self,
        procedures: tuple[str, ...],
        models: list[Any],
        class_means: np.ndarray,
        class_counts: np.ndarray,
        first: int,
    ) -> None:
        self.procedures = procedures
        self.models = models
        self.class_means = np.asarray(class_means, np.float32)
        self.class_counts = np.asarray(class_counts, np.int64)
        self.first = int(first)

    @classmethod
    def fit(
        cls, dataset: TactileDataset, new_model: Callable[[], Any], progress: bool = False
    ) -> ProcedureModels:
        """One model per procedure of ``dataset`` (``new_model()`` makes each, unfitted)."""
        k = dataset.n_classes
        counts = np.bincount(dataset.labels, minlength=k)
        sums = np.zeros((k, int(np.prod(dataset.input_shape))), np.float64)
        np.add.at(sums, dataset.labels, dataset.samples.reshape(len(dataset), -1))
        means = (sums / np.maximum(counts, 1)[:, None]).reshape(k, *dataset.input_shape)
        models = [
            new_model().fit(dataset.procedure_view(j), progress=progress)
            for j in range(len(dataset.procedures))
        ]
        out = cls(dataset.procedures, models, means, counts, 0)
        out.first = out._first_procedure()
        return out

    # ---------------------------------------------------------------- answering
    def _block(self, j: int) -> slice:
        return block(self.procedures, self.class_means.shape[1:], j)

    def scores(
        self, x: np.ndarray, keep: np.ndarray, threshold: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(novelty scores, known, novel probabilities) of samples ``x`` from the procedures
        ``keep``, fused; the scores relative to ``threshold`` (the whole model's)."""
        parts = [self.models[j]._all_scores(x[:, self._block(j)]) for j in keep]
        margin = np.mean(
            [s - m.novelty_threshold for (s, _, _), m in zip(parts, self._at(keep), strict=True)],
            axis=0,
        )
        known = np.mean([k for _, k, _ in parts], axis=0)
        novel = None if parts[0][2] is None else np.mean([n for _, _, n in parts], axis=0)
        return threshold + margin, known, novel

    def attribute_proba(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        return np.mean([self.models[j]._attribute_proba(x[:, self._block(j)]) for j in keep], 0)

    def _at(self, keep: np.ndarray) -> list[Any]:
        return [self.models[j] for j in keep]

    def next_procedures(
        self,
        known_p: np.ndarray,
        used: np.ndarray,
        ask: np.ndarray,
        seconds: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N,) index of the procedure to do next for the rows of ``ask`` (-1 elsewhere):
        the largest expected gain per second of robot time, each procedure taking
        ``seconds`` ((P,); default ``seconds_of`` its name). Where no procedure left is
        expected to gain (a confident answer held for ``MIN_PROCEDURES``), the smallest
        expected loss times seconds: loss divided by seconds made the slowest procedure
        look the least bad."""
        out = np.full(len(known_p), -1, np.int64)
        rows = np.flatnonzero(ask)
        if not len(rows):
            return out
        gain = self.expected_gains(known_p[rows], used[rows])
        if seconds is None:
            seconds = seconds_of(self.procedures)
        s = np.asarray(seconds, np.float64)[None, :]
        with np.errstate(invalid="ignore"):  # -inf (done) stays -inf either way
            score = np.where(gain > 0, gain / s, gain * s)
        out[rows] = score.argmax(axis=1)
        return out

    def expected_gains(self, known_p: np.ndarray, used: np.ndarray) -> np.ndarray:
        """(N, P) the expected change of the probability of each row's likely classes
        (weighted by it) after each procedure it has not done; -inf for those it did."""
        m = min(CANDIDATES, known_p.shape[1])
        cands = np.argpartition(-known_p, m - 1, axis=1)[:, :m]  # (N, m)
        p_c = np.take_along_axis(known_p, cands, axis=1)
        w = p_c / np.maximum(p_c.sum(axis=1, keepdims=True), 1e-12)
        n_used = used.sum(axis=1, keepdims=True).astype(np.float64)
        gain = np.full((len(known_p), len(self.procedures)), -np.inf)
        for j in range(len(self.procedures)):
            todo = ~used[:, j]
            if not todo.any():
                continue
            flat = cands[todo].ravel()
            q = self.models[j]._known_proba(self.class_means[flat][:, self._block(j)])
            q_true = q[np.arange(len(flat)), flat].reshape(-1, m)  # what j gives class c
            after = (n_used[todo] * p_c[todo] + q_true) / (n_used[todo] + 1.0)
            gain[todo, j] = (w[todo] * (after - p_c[todo])).sum(axis=1)
        return gain

    def _first_procedure(self) -> int:
        """The procedure with the largest expected gain per second before any touch: the
        probability its model puts on each class's typical touch, above chance (1 / K),
        per second of robot time (``seconds_of``)."""
        k = len(self.class_means)
        score = np.zeros(len(self.procedures))
        for j, model in enumerate(self.models):
            for a in range(0, k, _ROWS):
                q = model._known_proba(self.class_means[a : a + _ROWS][:, self._block(j)])
                score[j] += q[np.arange(len(q)), np.arange(a, a + len(q))].sum()
        gain = score / k - 1.0 / k
        return int((gain / seconds_of(self.procedures)).argmax())

    # ---------------------------------------------------------------- lifecycle
    def synced(
        self, parent: Any, change: Callable[[Any, int], None] | None = None
    ) -> ProcedureModels:
        """These models with ``parent``'s classes (its registry, one-shot samples cut to
        each procedure's block), each then changed by ``change(model, j)``: a copy, the
        original untouched."""
        out = copy.copy(self)
        out.models = []
        for j, model in enumerate(self.models):
            m = copy.deepcopy(model)
            reg = copy.deepcopy(parent.registry)
            rows = self._block(j)
            reg.novel_samples = {n: x[:, rows] for n, x in reg.novel_samples.items()}
            m.registry = reg
            if change is not None:
                change(m, j)
            out.models.append(m)
        return out

    def grown(self, parent: Any, samples: np.ndarray, labels: np.ndarray) -> ProcedureModels:
        """``synced`` after ``parent`` learnt ``samples`` of known classes ``labels``: each
        model learns its block of them, and the class means take them in."""
        k = len(parent.registry.known_names)
        counts = np.concatenate([self.class_counts, np.zeros(k - len(self.class_counts), np.int64)])
        means = np.concatenate(
            [self.class_means, np.zeros((k - len(self.class_means), *self.class_means.shape[1:]))]
        ).astype(np.float64)
        add = np.bincount(labels, minlength=k)
        sums = means.reshape(k, -1) * counts[:, None]
        np.add.at(sums, labels, samples.reshape(len(samples), -1))
        counts = counts + add
        means = (sums / np.maximum(counts, 1)[:, None]).reshape(means.shape)

        def grow(model: Any, j: int) -> None:
            model._grow_known(samples[:, self._block(j)], labels)

        out = self.synced(parent, grow)
        out.class_means, out.class_counts = means.astype(np.float32), counts
        return out

    def refit_attributes(self, parent: Any, dataset: TactileDataset) -> ProcedureModels:
        """``synced`` after ``parent`` refitted its attribute parts on ``dataset`` (its
        training samples, which may not name their procedures): each model refits on its
        block of them."""

        def refit(model: Any, j: int) -> None:
            model._refit_attributes(
                TactileDataset(
                    samples=dataset.samples[:, self._block(j)],
                    labels=dataset.labels,
                    trials=dataset.trials,
                    class_attributes=dataset.attribute_values,
                    attribute_names=dataset.attribute_names,
                    class_names=dataset.class_names,
                )
            )

        return self.synced(parent, refit)

    # -------------------------------------------------------------- persistence
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        arrays = {"class_means": self.class_means, "class_counts": self.class_counts}
        metas = []
        for j, model in enumerate(self.models):
            meta, parts = model.get_state()
            metas.append(
                {
                    "method_state": meta,
                    "novelty_threshold": model.novelty_threshold,
                    "input_shape": list(model.input_shape),
                }
            )
            arrays.update({f"{j}/{key}": value for key, value in parts.items()})
        return {"procedures": list(self.procedures), "first": self.first, "models": metas}, arrays

    @classmethod
    def from_state(
        cls,
        meta: dict[str, Any],
        arrays: dict[str, np.ndarray],
        parent: Any,
    ) -> ProcedureModels:
        """The models ``get_state`` stored, with ``parent``'s classes."""
        models = []
        for j, entry in enumerate(meta["models"]):
            prefix = f"{j}/"
            model = type(parent)()
            model.input_shape = tuple(int(s) for s in entry["input_shape"])
            model.procedures = (meta["procedures"][j],)
            model.registry = copy.deepcopy(parent.registry)
            model.registry.novel_samples = {}
            model.novelty_threshold = float(entry["novelty_threshold"])
            model.set_state(
                entry["method_state"],
                {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)},
            )
            models.append(model)
        out = cls(
            tuple(meta["procedures"]),
            models,
            arrays["class_means"],
            arrays["class_counts"],
            int(meta["first"]),
        )
        return out.synced(parent, lambda model, j: model._refit_novel())
