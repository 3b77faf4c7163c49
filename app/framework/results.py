"""What a recognizer answers, and how its answers are ranked.

``RecognitionBatch`` holds a batch's answers as arrays (what the service serialises);
``Recognition`` and ``ClassScore`` are one answer as Python objects. ``rows_batch`` and
``one_row_batch`` build a batch from the scores a recognizer computed: each row is routed
by its novelty score to the known-class or the novel-class probabilities, and the top k of
those are ranked by ``ranked`` (a stable order: among equal values the lower index first).

A broken sensor is not answered as an object. An answer whose input is an outlier
(``input_outlier``, ``app.framework.input_health``: all zeros, a saturated sensor, a dead
channel) abstains by default (``outliers="abstain"``): its ``kind`` is ``"input_outlier"``,
``class_name`` (and ``class_id``) None, ``is_novel`` None (it claims neither a known nor a
novel object) and ``top_k`` empty; its novelty score, input health and procedures stay.
``outliers="answer"`` gives the model's guess as for any other input (``kind`` ``known``
or ``novel``), ``input_outlier`` still true. A model without an input profile never
abstains (its answers' ``input_outlier`` is None).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from app.framework.state import KNOWN_KEPT, MODEL_DEFAULT

#: what an answer to an input outlier is: ``"abstain"`` (the default: no object named) or
#: ``"answer"`` (the model's guess, flagged ``input_outlier``)
ABSTAIN, ANSWER = "abstain", "answer"
OUTLIER_POLICIES = (ABSTAIN, ANSWER)
#: the ``kind`` of an answer that abstained because its input is an outlier
INPUT_OUTLIER = "input_outlier"


def check_outliers(outliers: str) -> str:
    """``outliers`` when it is one of ``OUTLIER_POLICIES``; ValueError naming them else."""
    if outliers not in OUTLIER_POLICIES:
        raise ValueError(
            f"outliers must be one of {', '.join(map(repr, OUTLIER_POLICIES))}, got {outliers!r}"
        )
    return outliers


class ClassScore(NamedTuple):
    class_name: str
    probability: float


class Recognition(NamedTuple):
    """The answer for one sample; one that abstained on an input outlier names no class
    (``class_name`` None, ``kind`` ``"input_outlier"``, ``is_novel`` None, no ``top_k``)."""

    class_name: str | None
    kind: str  # "known" | "novel" | "input_outlier"
    is_novel: bool | None
    novelty_score: float
    top_k: tuple[ClassScore, ...]
    procedures_used: tuple[str, ...] = ()
    next_procedure: str | None = None  # the procedure to do next; None: stop
    #: the sample lies outside the training data's channel ranges (``app.framework.
    #: input_health``); None where the model holds no input profile (fitted before them)
    input_outlier: bool | None = None
    input_outlier_score: float | None = None
    #: the threshold the answer was routed by, the share of known touches it kept at fit
    #: (None: the model's own threshold) and which of the two (``"known_kept"``,
    #: ``"model_default"``)
    novelty_threshold: float | None = None
    known_kept: float | None = None
    operating_point: str | None = None
    calibrated_touches: int | None = None


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
    #: (N,) float64 how far each input lies outside the training data's channel ranges,
    #: and (N,) bool whether that is beyond the threshold (``app.framework.input_health``);
    #: None where the model holds no input profile
    input_outlier_score: np.ndarray | None = None
    input_outlier: np.ndarray | None = None
    #: (n, S) float32 the compressed channel statistics of each sample answered, which the
    #: service's drift monitor keeps (``InputProfile.features``): one row per *sample*, more
    #: rows than answers where groups fused samples (a slice keeps them only where each
    #: answer is one sample); None where the model holds no input profile
    input_statistics: np.ndarray | None = None
    #: (N,) float64 the novelty threshold each answer was routed by (novel above it), and
    #: the share of held-out known touches that threshold kept known at fit, the operating
    #: point asked for (None: the model's own threshold); None where not recorded
    novelty_threshold: np.ndarray | None = None
    known_kept: float | None = None
    #: (N,) int64 the touches fused in the held-out groups of the calibration curve each
    #: threshold was read off (1: single touches; 0: a raw-trial model's single images);
    #: None at the model's own threshold
    calibrated_touches: np.ndarray | None = None

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
            None if self.input_outlier_score is None else self.input_outlier_score[rows],
            None if self.input_outlier is None else self.input_outlier[rows],
            self.input_statistics[rows]
            if self.input_statistics is not None and len(self.input_statistics) == len(self)
            else None,
            None if self.novelty_threshold is None else self.novelty_threshold[rows],
            self.known_kept,
            None if self.calibrated_touches is None else self.calibrated_touches[rows],
        )

    def health_fields(self) -> list[tuple[bool | None, float | None]]:
        """(``input_outlier``, ``input_outlier_score``) of each answer; None, None where the
        model holds no input profile."""
        if self.input_outlier is None or self.input_outlier_score is None:
            return [(None, None)] * len(self)
        return list(
            zip(self.input_outlier.tolist(), self.input_outlier_score.tolist(), strict=True)
        )

    def operating_fields(
        self,
    ) -> list[tuple[float | None, float | None, str | None, int | None]]:
        """(``novelty_threshold``, ``known_kept``, ``operating_point``,
        ``calibrated_touches``) of each answer: the threshold it was routed by, the share of
        known touches asked for (``"known_kept"``) or none, the model's own threshold
        (``"model_default"``), and the touches of the curve the threshold was read off."""
        if self.novelty_threshold is None:
            return [(None, None, None, None)] * len(self)
        point = MODEL_DEFAULT if self.known_kept is None else KNOWN_KEPT
        kept = self.known_kept
        if self.calibrated_touches is None:
            return [(t, kept, point, None) for t in self.novelty_threshold.tolist()]
        return [
            (t, kept, point, k)
            for t, k in zip(
                self.novelty_threshold.tolist(), self.calibrated_touches.tolist(), strict=True
            )
        ]

    def procedure_fields(self) -> list[tuple[list[str], str | None]]:
        """(``procedures_used``, ``next_procedure``) of each answer, by name."""
        names = self.procedures
        if self.procedures_used is None or self.next_procedure is None:
            return [(list(names), None)] * len(self)
        # on Python lists: numpy's per-call cost on each row of a few procedures was most of it
        return [
            ([n for n, u in zip(names, used, strict=True) if u], names[nxt] if nxt >= 0 else None)
            for used, nxt in zip(
                self.procedures_used.tolist(), self.next_procedure.tolist(), strict=True
            )
        ]

    @property
    def class_kinds(self) -> list[str]:
        """``"known"`` or ``"novel"`` for each of ``class_names``."""
        return ["known"] * self.n_known + ["novel"] * (len(self.class_names) - self.n_known)

    @property
    def is_novel_class(self) -> np.ndarray:
        """(N,) bool: the answer is a novel class (FC_Z), not a known one (FC_Y)."""
        return self.top_index[:, 0] >= self.n_known

    def records(
        self, class_ids: Mapping[str, int | None] | None = None, outliers: str = ABSTAIN
    ) -> list[dict[str, Any]]:
        """The answers as JSON-ready dicts, in the shape of ``POST /v1/recognize``'s results;
        with ``class_ids`` (class name → the store's id) every class named carries its
        ``class_id`` too. An input outlier's answer abstains unless ``outliers`` is
        ``"answer"`` (the module docstring). Built straight from the arrays: building
        pydantic models first cost more than the forward pass of a sample."""
        names = self.class_names
        label = (
            [{"class_name": n} for n in names]
            if class_ids is None
            else [{"class_id": class_ids.get(n), "class_name": n} for n in names]
        )
        return self.labelled_records(label, self.class_kinds, outliers)

    def labelled_records(
        self, label: Sequence[Mapping[str, Any]], kinds: Sequence[str], outliers: str = ABSTAIN
    ) -> list[dict[str, Any]]:
        """``records`` from each class's label dict and kind, which a caller answering many
        batches of one model (the service) builds once."""
        out = [
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
                "input_outlier": outlier,
                "input_outlier_score": outlier_score,
                "novelty_threshold": threshold,
                "known_kept": kept,
                "operating_point": point,
                "calibrated_touches": calibrated,
            }
            for idx, top_p, novel, score, (used, nxt), (outlier, outlier_score), (
                threshold,
                kept,
                point,
                calibrated,
            ) in zip(
                self.top_index.tolist(),
                self.top_probability.tolist(),
                self.is_novel.tolist(),
                self.novelty_score.tolist(),
                self.procedure_fields(),
                self.health_fields(),
                self.operating_fields(),
                strict=True,
            )
        ]
        for i in self._abstaining(outliers):
            record = out[i]
            record.update(dict.fromkeys(label[0], None))
            record.update(kind=INPUT_OUTLIER, is_novel=None, top_k=[])
        return out

    def _abstaining(self, outliers: str) -> list[int]:
        """The rows whose answer abstains under ``outliers``: the input outliers, unless
        ``outliers`` is ``"answer"``."""
        if outliers is not ABSTAIN and check_outliers(outliers) == ANSWER:
            return []
        flags = self.input_outlier
        if flags is None or not flags.any():
            return []
        return np.flatnonzero(flags).tolist()

    def answers(self, outliers: str = ABSTAIN) -> list[Recognition]:
        """The answers as ``Recognition`` objects; an input outlier's abstains unless
        ``outliers`` is ``"answer"`` (the module docstring)."""
        names, kinds = self.class_names, self.class_kinds
        out = [
            Recognition(
                names[idx[0]],
                kinds[idx[0]],
                nov,
                score,
                tuple(ClassScore(names[j], q) for j, q in zip(idx, tp, strict=True) if j >= 0),
                tuple(used),
                nxt,
                outlier,
                outlier_score,
                *operating,
            )
            for idx, tp, nov, score, (used, nxt), (outlier, outlier_score), operating in zip(
                self.top_index.tolist(),
                self.top_probability.tolist(),
                self.is_novel.tolist(),
                self.novelty_score.tolist(),
                self.procedure_fields(),
                self.health_fields(),
                self.operating_fields(),
                strict=True,
            )
        ]
        for i in self._abstaining(outliers):
            out[i] = out[i]._replace(class_name=None, kind=INPUT_OUTLIER, is_novel=None, top_k=())
        return out


def rows_batch(
    scores: np.ndarray,
    known_p: np.ndarray,
    novel_p: np.ndarray | None,
    top_k: int,
    threshold: float,
    known_names: Sequence[str],
    novel_names: Sequence[str],
) -> RecognitionBatch:
    """The answers of any number of rows: a row whose novelty score is above ``threshold``
    (a number, or one per row; the batch records it) is answered from ``novel_p`` (where
    there are novel classes), the others from ``known_p``; each ranks its top ``top_k`` (at
    least 1). ``one_row_batch`` must match it bit for bit."""
    novel = scores > threshold
    n, k, n_known = len(scores), max(1, top_k), len(known_names)
    # Route, then rank top-k for each classifier's rows at once.
    # Without novel classes a novel sample can only be answered from the known ones.
    use_novel = novel & (novel_p is not None)
    n_novel = int(np.count_nonzero(use_novel))
    if n_novel in (0, n):
        # one classifier answers every row (always so for one sample): no masked copies
        probs, offset = (known_p, 0) if n_novel == 0 else (novel_p, n_known)
        top_index, top_p = top_k_ranks(probs, k, offset)
    else:
        top_index = np.full((n, k), -1, np.int64)
        top_p = np.full((n, k), np.nan)
        for probs, offset, rows in ((known_p, 0, ~use_novel), (novel_p, n_known, use_novel)):
            top_index[rows], top_p[rows] = top_k_ranks(probs[rows], k, offset)
    return RecognitionBatch(
        joined_names(known_names, novel_names),
        n_known,
        top_index,
        top_p,
        novel,
        scores.astype(np.float64),
        novelty_threshold=np.full(n, threshold, np.float64),
    )


def one_row_batch(
    scores: np.ndarray,
    known_p: np.ndarray,
    novel_p: np.ndarray | None,
    top_k: int,
    threshold: float,
    known_names: Sequence[str],
    novel_names: Sequence[str],
) -> RecognitionBatch:
    """``rows_batch`` for a batch of one row, bit for bit: the same comparison routes it and
    the same ``ranked`` orders its row, without the machinery for many rows (about half the
    cost for one sample)."""
    novel = scores > threshold
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
        class_names=joined_names(known_names, novel_names),
        n_known=len(known_names),
        top_index=order[None],
        top_probability=value[None],
        is_novel=novel,
        novelty_score=scores.astype(np.float64),
        procedures=(),
        procedures_used=None,
        next_procedure=None,
        input_outlier_score=None,
        input_outlier=None,
        input_statistics=None,
        novelty_threshold=np.full(1, threshold, np.float64),
        known_kept=None,
        calibrated_touches=None,
    )
    return batch


def joined_names(known_names: Sequence[str], novel_names: Sequence[str]) -> tuple[str, ...]:
    """``(*known_names, *novel_names)``: the same tuple for the same two sequences while
    their lengths stay (a model's registry replaces its name lists, never edits them).
    Joining visits every class, for every answer, and the service checks the tuple against
    the one its labels were built for, ``is`` first (``RecognitionService._model_labels``):
    at 10,000 objects one sample's answer took 440–483 µs joining, 298–300 µs without."""
    key = (id(known_names), id(novel_names))
    held = _JOINED.get(key)
    if held is not None and held[2] == (len(known_names), len(novel_names)):
        return held[3]
    names = (*known_names, *novel_names)
    with _JOINED_LOCK:  # requests answer in threads
        if len(_JOINED) >= _JOINED_KEPT:
            del _JOINED[next(iter(_JOINED))]  # the oldest: models in turn, not all kept
        # the sequences held, so that their ids stay theirs while the entry lives
        _JOINED[key] = (known_names, novel_names, (len(known_names), len(novel_names)), names)
    return names


# joined name tuples of the last few (known, novel) name sequences, by their ids
_JOINED: dict[tuple[int, int], tuple[Sequence[str], Sequence[str], tuple[int, int], tuple]] = {}
_JOINED_KEPT = 8
_JOINED_LOCK = threading.Lock()


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
    if k == 1:  # the largest alone: no copy to take it out of
        return p.argmax(axis=1)[:, None]
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


def top_k_ranks(p: np.ndarray, k: int, offset: int) -> tuple[np.ndarray, np.ndarray]:
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
