"""What ``POST /v1/recognize`` does once its body is parsed, behind one dependency.

Small requests (up to ``coalesce`` samples) are validated on their own, so each gets
its own errors, then share forward passes through the RecognitionBatcher; larger
ones run alone in the thread pool. Recognitions are counted for /metrics.
"""

from __future__ import annotations

import numpy as np
from fastapi.concurrency import run_in_threadpool

from app.framework.recognizer import RecognitionBatch
from app.service.batcher import RecognitionBatcher
from app.service.holder import LoadedModel
from app.service.metrics import Metrics
from app.store.enums import ClassKind


class RecognitionService:
    def __init__(
        self,
        metrics: Metrics,
        top_k: int,
        batch_limit: int,
        coalesce: int = 64,
        batcher: RecognitionBatcher | None = None,
    ) -> None:
        self.metrics = metrics
        self.top_k = top_k
        self.batch_limit = batch_limit
        self.coalesce = coalesce
        self.batcher = batcher or RecognitionBatcher()

    async def recognize(
        self, model: LoadedModel, samples: np.ndarray | list, n: int
    ) -> RecognitionBatch:
        """Recognise ``n`` samples with ``model``, the caller's snapshot to the end."""
        rec = model.recognizer
        if n <= self.coalesce:
            x = rec.validate_samples(samples)
            results = await self.batcher.recognize(model, x, self.top_k)
        else:
            results = await run_in_threadpool(rec.recognize_batch, samples, self.top_k)
        return self._counted(results)

    async def recognize_object(
        self, model: LoadedModel, samples: np.ndarray | list
    ) -> RecognitionBatch:
        """One answer for all ``samples``, touches of one object, their evidence fused."""
        groups = np.zeros(len(samples), np.int64)
        rec = model.recognizer
        return self._counted(
            await run_in_threadpool(rec.recognize_batch, samples, self.top_k, groups)
        )

    async def recognize_trials(
        self, model: LoadedModel, trials: list, same_object: bool = False
    ) -> RecognitionBatch:
        """One answer per raw trial from all its fingers (with ``same_object``, one for all
        the trials): featurized by the model's own featurizer."""
        rec = model.recognizer

        def run() -> RecognitionBatch:
            images, groups = rec.trial_samples(trials)
            if same_object:
                groups = np.zeros_like(groups)
            return rec.recognize_batch(images, self.top_k, groups)

        return self._counted(await run_in_threadpool(run))

    def _counted(self, results: RecognitionBatch) -> RecognitionBatch:
        novel = int(results.is_novel_class.sum())
        for kind, count in ((ClassKind.KNOWN, len(results) - novel), (ClassKind.NOVEL, novel)):
            if count:
                self.metrics.recognitions.labels(kind).inc(count)
        return results
