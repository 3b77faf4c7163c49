"""``prototypes``' scores for a few samples at a time: the general path's answers with a
fraction of its per-call cost.

For one sample the general path (``PrototypeRecognizer._all_scores``) spent more than half
its time in numpy's and faiss's per-call costs on tiny arrays: the scaler's five calls and
``np.clip``'s wrapper, ``SubclassEmbedding.transform``'s blocked loop, faiss's search (an
OpenMP region) before the exact distances, and ``class_log_posterior``'s dozen calls on a
(1, k, k) array of class matches. This path, for batches of at most
``PrototypeRecognizer.small_batch_max`` complete samples of a model without a reduction:

- scales the samples in one compiled kernel after numpy's ``log1p`` (the scaler's
  element-wise steps: copysign, minus the centre, over the scale, the clip; IEEE gives
  them the same bits in any order) and centres them on the embedding's centre there too,
  so the one matrix product, ``(z - centre) @ projection`` (BLAS's gemv, as the general
  path calls it on a row of the same shape and layout), gives the general path's
  coordinates bit for bit;
- finds the ``search_k`` nearest prototypes of an exact index by faiss's distances to
  every prototype (``PrototypeSearch.squared_to_all``: the function the general path
  re-scores its candidates with, so the same bits) and a stable sort of them in a kernel,
  with no faiss search before them (an HNSW index searches as the general path does);
- computes the class posterior, the known probabilities and the novelty score in one
  compiled kernel from per-prototype constants kept with the scorer (``1 / (2 tau v)``,
  ``-dims/2 log v + log(n / class n)``, ``1 / v``). Its exp and log are libm's and its sums
  run in candidate order, so these agree with the general path's to rounding (a few units
  in the last place; ``tests/methods/test_prototypes_small_batch.py`` checks 1e-9), not bit
  for bit.

The novel classes' part is the general path's own code (``_novel_from``), given the
coordinates and the candidates found here, and the zero-shot posterior from constants
taken once per novel part (``ZeroShotConstants``: ``zero_shot_proba``'s calls on the
samples, without its per-call work on the class vectors and the prior): the same bits as
the general path from the same inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from app.methods.attributes import dap_class_terms, impute, softmax


class PrototypeSmallBatch:
    """(novelty scores, known probabilities, embedded rows, scaled rows, candidates) of
    flat float32 samples, as ``PrototypeRecognizer`` computes them, from constants taken
    once of a fitted model: its scaler, its embedding, its prototypes' classes and counts,
    ``tau`` and the novelty score's distance weight. A model whose prototypes change
    (a promotion) builds a new scorer (``PrototypeRecognizer._few``)."""

    def __init__(self, model) -> None:
        scaler, emb = model.scaler_, model.embedding_
        d = int(np.prod(model.input_shape))
        center = np.asarray(scaler.center_, np.float32).reshape(-1)
        scale = np.asarray(scaler.scale_, np.float32).reshape(-1)
        if center.shape != (d,) or scale.shape != (d,):
            raise ValueError("the small-batch path needs the scaler's statistics per feature")
        # the kernel's per-feature inputs in one array: each argument costs the dispatcher
        self.per_feature = np.ascontiguousarray(
            np.stack([center, scale, np.asarray(emb.center_, np.float32).reshape(-1)])
        )
        self.clip = np.float32(scaler.clip)
        self.log_compress = bool(scaler.log_compress)
        self.projection = emb.projection_
        self.search = model.search_
        self.k = int(model.search_k)
        tau, dims = float(model.tau_), self.projection.shape[1]
        count = np.asarray(model.proto_count_, np.float64)
        v = 1.0 + 1.0 / count
        cls = np.asarray(model.proto_class_, np.int64)
        share = np.log(count / model.class_n_[cls]) - 0.5 * dims * np.log(v)
        # per prototype: its class, 1 / (2 tau v), its log-weight's constant, 1 / v
        self.proto = np.ascontiguousarray(
            np.stack([cls.astype(np.float64), 1.0 / (2.0 * tau * v), share, 1.0 / v])
        )
        self.settings = np.array([dims * tau, float(model.distance_weight_)])
        self.n_classes = len(model.registry.known_names)
        self._key = _key(model)

    def fits(self, model) -> bool:
        """Whether this scorer was built from ``model``'s present space and prototypes
        (the same objects: a promotion or a new fit replaces them)."""
        return all(a is b for a, b in zip(self._key, _key(model), strict=True))

    def scores(self, x: np.ndarray):
        """(novelty (N,), known probabilities (N, K), coordinates e (N, D), scaled rows z
        (N, F), (candidate ids, their squared distances)) of flat float32 rows ``x``."""
        n, d = len(x), self.per_feature.shape[1]
        z, zc = np.empty((n, d), np.float32), np.empty((n, d), np.float32)
        if self.log_compress:  # RobustInputScaler._compress: log1p(|x|), then x's sign
            mag = np.abs(x)
            np.log1p(mag, out=mag)
        else:
            mag = x
        _scale(x, mag, self.per_feature, self.clip, self.log_compress, z, zc)
        e = zc @ self.projection
        every = self.search.squared_to_all(e)
        if every is None:  # an HNSW graph: its own search
            ids, dist = self.search.nearest(e, self.k)
        else:
            k = min(self.k, every.shape[1])
            ids, dist = np.empty((n, k), np.int64), np.empty((n, k))
            _nearest_k(every, ids, dist)
        known = np.zeros((n, self.n_classes))
        novelty = np.empty(n)
        _posterior(ids, dist, self.proto, self.settings, known, novelty)
        return novelty, known, e, z, (ids, dist)

    def zero_shot(self, model, z: np.ndarray) -> np.ndarray:
        """``model._zero_shot(z)`` from constants taken once per novel part."""
        c = getattr(self, "_zero", None)
        if c is None or not c.fits(model):
            c = self._zero = ZeroShotConstants(model)
        return c.proba(z)


class ZeroShotConstants:
    """What ``zero_shot_proba`` derives from the model alone on every call, taken once:
    DAP's clipped prior, its class-vector terms and prior term, the autoencoder's unit
    class vectors. ``proba`` then makes the calls ``zero_shot_proba`` makes on the samples,
    on arrays of the same shapes, dtypes and layout (the constants' transposed views as
    there): the same bits."""

    def __init__(self, model) -> None:
        reg = model.registry
        self.attributes = model.attributes_
        self.clip = float(model.dap_clip)
        q = np.clip(model.prior_, self.clip, 1 - self.clip)
        self.present, self.absent = dap_class_terms(reg.novel_attributes)
        self.log_prior = np.log(q) @ self.present.T + np.log1p(-q) @ self.absent.T
        self.sae = model.sae_
        self.temperature = float(model.sae_temperature)
        self.unit_vectors = None
        if self.sae is not None:
            vectors = np.asarray(impute(reg.novel_attributes, model.prior_), np.float64)
            self.unit_vectors = _unit(vectors)
        self._key = (model.attributes_, model.prior_, model.sae_, reg.novel_attributes)

    def fits(self, model) -> bool:
        key = (model.attributes_, model.prior_, model.sae_, model.registry.novel_attributes)
        return all(a is b for a, b in zip(self._key, key, strict=True))

    def proba(self, z: np.ndarray) -> np.ndarray:
        """(N, L) ``zero_shot_proba`` of scaled rows ``z``."""
        p = np.clip(self.attributes.predict_proba(z), self.clip, 1 - self.clip)
        scores = np.log(p) @ self.present.T + np.log1p(-p) @ self.absent.T
        scores = scores - self.log_prior[None, :]
        if self.sae is not None:
            projected = np.asarray(z, np.float32) @ np.asarray(self.sae, np.float32).T
            cosine = _unit(projected.astype(np.float64)) @ self.unit_vectors.T
            scores = scores + self.temperature * cosine
        return softmax(scores)


def _unit(m: np.ndarray) -> np.ndarray:
    """Rows over max(their norm, 1e-12), as ``cosine_scores`` computes them."""
    return m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)


def _key(model) -> tuple:
    return (
        model.scaler_,
        model.embedding_,
        model.search_,
        model.proto_count_,
        model.proto_class_,
        model.class_n_,
        model.tau_,
        model.distance_weight_,
    )


@njit(cache=True, nogil=True, error_model="numpy")
def _scale(x, mag, per_feature, clip, log_compress, z, zc):
    """RobustInputScaler.transform's steps after log1p (into ``z``), and the rows less the
    embedding's centre (``zc``), as SubclassEmbedding.transform subtracts it."""
    center, scale, emb_center = per_feature[0], per_feature[1], per_feature[2]
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            v = np.copysign(mag[i, j], x[i, j]) if log_compress else mag[i, j]
            v = (v - center[j]) / scale[j]
            v = min(max(v, -clip), clip)
            z[i, j] = v
            zc[i, j] = v - emb_center[j]


@njit(cache=True, nogil=True, error_model="numpy")
def _nearest_k(every, ids, dist):
    """Of each row of squared distances ``every`` (float32), the ``ids.shape[1]`` smallest,
    nearest first (equal ones by id: a stable sort, as ``PrototypeSearch._nearest``'s
    re-ranking), their ids and their distances as float64."""
    k = ids.shape[1]
    for i in range(every.shape[0]):
        order = np.argsort(every[i], kind="mergesort")
        for c in range(k):
            ids[i, c] = order[c]
            dist[i, c] = np.float64(every[i, order[c]])


@njit(cache=True, nogil=True, error_model="numpy")
def _posterior(ids, dist, proto, settings, known, novelty):
    """``class_log_posterior``, ``_dense`` of its exp and ``novelty_scores`` of each row's
    candidates ``ids`` at squared distances ``dist`` (``proto``: each prototype's class,
    1 / (2 tau v), log-weight constant and 1 / v; ``settings``: dims x tau, the distance
    weight)."""
    k = ids.shape[1]
    cls = np.empty(k, np.int64)
    logd = np.empty(k)
    w = np.empty(k)
    dims_tau, weight = settings[0], settings[1]
    for i in range(ids.shape[0]):
        top = -np.inf
        nearest = np.inf
        for c in range(k):
            j = ids[i, c]
            cls[c] = np.int64(proto[0, j])
            v = -dist[i, c] * proto[1, j] + proto[2, j]
            logd[c] = v
            top = max(top, v)
            nearest = min(nearest, dist[i, c] * proto[3, j])
        if not np.isfinite(top):
            top = 0.0
        total = 0.0
        for c in range(k):
            w[c] = np.exp(logd[c] - top)
            total += w[c]
        log_total = np.log(max(total, 1e-300))
        best = -np.inf
        for c in range(k):
            same = 0.0
            for b in range(k):
                if cls[b] == cls[c]:
                    same += w[b]
            logp = np.log(max(same, 1e-300)) - log_total
            best = max(best, logp)
            known[i, cls[c]] = np.exp(logp)
        score = 1.0 - np.exp(best)
        if weight != 0.0:
            score += weight * np.log(nearest / dims_tau + 1e-12)
        novelty[i] = score
