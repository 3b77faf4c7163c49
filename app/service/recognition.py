"""What ``POST /v1/recognize`` does once its body is parsed, behind one dependency.

Small requests (up to ``coalesce`` samples) are validated on their own, so each gets
its own errors, then share forward passes through the RecognitionBatcher, which counts
each pass, keeps its inputs' health (``app.service.input_monitor``) and builds its answers'
records once (``_finish``), each request then taking its rows; larger ones run alone in the
thread pool. The answer's JSON is built here from the arrays, with what is constant per
model version (each class's name and store id) built once per served model.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import orjson
from fastapi.concurrency import run_in_threadpool

from app.framework.recognizer import (
    ABSTAIN,
    TARGET_CONFIDENCE,
    RecognitionBatch,
    TactileRecognizer,
    check_outliers,
)
from app.service.batcher import RecognitionBatcher
from app.service.holder import LoadedModel
from app.service.input_monitor import InputMonitor
from app.service.metrics import Metrics
from app.service.table_answers import Label, Table, answer_table, table_records
from app.store.enums import ClassKind


class RecognitionService:
    def __init__(
        self,
        metrics: Metrics,
        top_k: int,
        batch_limit: int,
        coalesce: int = 64,
        input_window: int = 256,
        known_kept: float | None = None,
        outliers: str = ABSTAIN,
    ) -> None:
        self.metrics = metrics
        # the service's operating point, for every model with a calibration curve; None:
        # each model's own threshold
        self.known_kept = known_kept
        # what an input outlier's answer is by default: "abstain" (no object) or "answer"
        self.outliers = check_outliers(outliers)
        self.inputs = InputMonitor(metrics, input_window)
        self.top_k = top_k
        self.batch_limit = batch_limit
        self.coalesce = coalesce
        # each pass counted and made into records once (_finish), its requests taking rows
        self.batcher = RecognitionBatcher(finish=self._finish)
        # the served model and its classes' labels ({"class_id", "class_name"}, and the
        # kind of each), built once per model: rebuilding them for 60 classes cost
        # ~15 µs of a single-sample request
        self._labels: tuple[LoadedModel, tuple[str, ...], int, list, list] | None = None
        self._recognized = {
            kind: metrics.recognitions.labels(kind) for kind in (ClassKind.KNOWN, ClassKind.NOVEL)
        }

    async def recognize(
        self,
        model: LoadedModel,
        samples: np.ndarray | list,
        n: int,
        target_confidence: float | None = None,
        known_kept: float | None = None,
        outliers: str | None = None,
    ) -> list[dict[str, Any]]:
        """The answers' records (``records``) of ``n`` samples recognised with ``model``,
        the caller's snapshot to the end; a ``target_confidence`` other than the model's
        default (None) runs alone. Novel above the threshold keeping ``known_kept`` of
        known touches (None: the service's ``known_kept``, else the model's own
        threshold); ``outliers`` None: the service's policy."""
        rec = model.recognizer
        kept = self._kept(rec, known_kept)
        policy = outliers or self.outliers
        if target_confidence is None and n <= self.coalesce:
            x = rec.validate_samples(samples, partial=True)
            return await self.batcher.recognize(model, x, self.top_k, kept, policy)
        target = TARGET_CONFIDENCE if target_confidence is None else target_confidence
        results = await run_in_threadpool(
            rec.recognize_batch, samples, self.top_k, None, target, kept
        )
        return self._finish(model, results, policy)

    def _finish(
        self, model: LoadedModel, results: RecognitionBatch, outliers: str
    ) -> list[dict[str, Any]]:
        """``results`` counted, their inputs observed, as records: once per batcher pass,
        whichever requests share it."""
        self._counted(model, results)
        return self.records(model, results, outliers)

    async def recognize_object(
        self,
        model: LoadedModel,
        samples: np.ndarray | list,
        target_confidence: float | None = None,
        known_kept: float | None = None,
    ) -> RecognitionBatch:
        """One answer for all ``samples``, touches of one object, their evidence fused."""
        groups = np.zeros(len(samples), np.int64)
        rec = model.recognizer
        target = TARGET_CONFIDENCE if target_confidence is None else target_confidence
        kept = self._kept(rec, known_kept)
        return self._counted(
            model,
            await run_in_threadpool(rec.recognize_batch, samples, self.top_k, groups, target, kept),
        )

    async def recognize_trials(
        self,
        model: LoadedModel,
        trials: list,
        same_object: bool = False,
        known_kept: float | None = None,
    ) -> RecognitionBatch:
        """One answer per raw trial from all its fingers (with ``same_object``, one for all
        the trials): featurized by the model's own featurizer."""
        rec = model.recognizer
        kept = self._kept(rec, known_kept)

        def run() -> RecognitionBatch:
            images, groups = rec.trial_samples(trials)
            touches = None  # one trial a group
            if same_object:  # every trial one touch of the object: the curve of that many
                groups, touches = np.zeros_like(groups), np.array([len(trials)])
            return rec.recognize_batch(images, self.top_k, groups, known_kept=kept, touches=touches)

        return self._counted(model, await run_in_threadpool(run))

    async def recognize_table(
        self,
        model: LoadedModel,
        objects: list[Label],
        samples: np.ndarray | None = None,
        trials: list | None = None,
        target_confidence: float | None = None,
        known_kept: float | None = None,
        outliers: str | None = None,
    ) -> Table:
        """A table of objects named jointly (``app.service.table_answers``): one label of
        ``objects`` per sample, or per raw trial; ``outliers`` None: the service's (an
        object that abstains takes no part in the naming)."""
        rec = model.recognizer
        kept = self._kept(rec, known_kept)
        policy = outliers or self.outliers
        table = await run_in_threadpool(
            answer_table,
            rec,
            objects,
            samples,
            trials,
            self.top_k,
            target_confidence,
            kept,
            policy,
        )
        self._counted(model, table.batch)
        return table

    def table_json(self, model: LoadedModel, table: Table, outliers: str | None = None) -> bytes:
        """The RecognizeResponse body of a table: one result per object (``table_records``)."""
        label, _ = self._model_labels(model, table.batch)
        by_name = dict(zip(table.batch.class_names, label, strict=True))
        kinds = dict(zip(table.batch.class_names, table.batch.class_kinds, strict=True))
        records = table_records(
            table, self.records(model, table.batch, outliers), by_name.__getitem__, kinds
        )
        return orjson.dumps({"model_version": model.version, "results": records})

    def _kept(self, rec: TactileRecognizer, known_kept: float | None) -> float | None:
        """The share of known touches an answer is routed by: the request's, else the
        service's where the model holds a calibration curve; None answers at the model's
        own threshold (``TactileRecognizer.operating_point``)."""
        return rec.operating_point(known_kept, self.known_kept)

    def _counted(self, model: LoadedModel, results: RecognitionBatch) -> RecognitionBatch:
        best = results.top_index[:, 0]
        n_known = results.n_known
        if len(best) <= 8:  # a robot's touch: plain Python beats numpy's per-call cost
            novel = sum(1 for i in best.tolist() if i >= n_known)
        else:
            novel = int(np.count_nonzero(best >= n_known))
        for kind, count in ((ClassKind.KNOWN, len(results) - novel), (ClassKind.NOVEL, novel)):
            if count:
                self._recognized[kind].inc(count)
        rec = model.recognizer
        self.inputs.observe(results, rec.input_profile_, _channel_names(rec))
        return results

    def to_json(
        self, model: LoadedModel, results: RecognitionBatch, outliers: str | None = None
    ) -> bytes:
        """The RecognizeResponse body (the schema documents it) of ``results``, answered
        by ``model``: ``{"model_version", "results"}``, each result what
        ``RecognitionBatch.records(model.class_ids, outliers)`` gives (a test holds them
        equal); ``outliers`` None: the service's."""
        return self.json_of(model, self.records(model, results, outliers))

    @staticmethod
    def json_of(model: LoadedModel, records: list[dict[str, Any]]) -> bytes:
        """The RecognizeResponse body of ``records`` answered by ``model``."""
        return orjson.dumps({"model_version": model.version, "results": records})

    def records(
        self, model: LoadedModel, results: RecognitionBatch, outliers: str | None = None
    ) -> list[dict[str, Any]]:
        """``results.records(model.class_ids, outliers)``, from labels built once per
        model; an input outlier's answer abstains unless ``outliers`` (None: the
        service's ``outliers``) is ``"answer"``."""
        label, kinds = self._model_labels(model, results)
        return results.labelled_records(label, kinds, outliers or self.outliers)

    def _model_labels(self, model: LoadedModel, results: RecognitionBatch) -> tuple[list, list]:
        cached = self._labels
        if (
            cached is not None
            and cached[0] is model
            and cached[2] == results.n_known
            and (cached[1] is results.class_names or cached[1] == results.class_names)
        ):
            return cached[3], cached[4]
        names, ids = results.class_names, model.class_ids
        label = [{"class_id": ids.get(n), "class_name": n} for n in names]
        kinds = results.class_kinds
        self._labels = (model, names, results.n_known, label, kinds)
        return label, kinds


def _channel_names(rec) -> tuple[str, ...]:
    """The names of a model's channels where it knows them (a raw-trial model's image rows,
    from its featurizer); () elsewhere (the channels are then numbered)."""
    featurizer = rec.featurizer
    return tuple(featurizer.channel_names) if featurizer is not None else ()
