"""``best``'s scores for a few samples at a time, bit-identical to the general path.

For one sample the general path (``KnownModel.scores`` and ``BestRecognizer._novel_from``)
costs several times its batch-amortised cost per sample: dozens of numpy calls on tiny
arrays, each paying its call overhead, plus constants recomputed on every call. This path:

- computes the model's constants once (``SmallBatchScorer`` is built per fitted model and
  novel part): DAP's prior term, the unit attribute vectors, the one-shot prototypes, the
  attribute model's fixed columns;
- fuses the exact element-wise steps (+ - * /, min, max, sqrt, copysign: IEEE gives the
  same bits in any order of elements) and the forest walk into compiled kernels; one
  sample walks a block of trees at once (``_walk_trees``: independent load chains, as
  ``forest._walk`` gets from a block of samples) and sums the leaves in tree order;
- leaves to numpy exactly what the general path does with numpy: every transcendental
  function (log, log1p, exp, tanh: numpy's SIMD versions need not round like libm), every
  sum along an axis (numpy sums pairwise) and every matrix product (BLAS), called on arrays
  of the same shapes and memory layout, so their bits are the general path's.

A cue whose weight is 0 in the novelty score (the entropy, in ``best``) is not computed:
its product with 0 adds nothing to the weighted sum.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from app.methods.attributes import dap_class_terms, impute
from app.methods.known import _EPS, _KNN, CUES, _nearest

if TYPE_CHECKING:
    from app.methods.best import BestRecognizer

_add = np.add.reduce
_ENTROPY = CUES.index("entropy")
_TREES = 8  # trees one sample takes down together (as forest._BLOCK samples)


class SmallBatchScorer:
    """(novelty scores, known probabilities, novel probabilities) of flat float32 samples,
    as ``BestRecognizer._all_scores`` computes them; built once per fitted model."""

    def __init__(self, model: BestRecognizer) -> None:
        cues = model.known_.cues_model
        forest, dist = cues.forest, cues.distances
        if forest._nodes is None:
            forest._prepare_walk()
        self.forest = forest
        self.n_classes = forest.n_classes
        # per feature: the scaler's centre and scale, the distance weights, the distance
        # centre (one array: each argument of a compiled call costs time to check)
        self.per_feature = np.stack(
            [
                cues.scaler.center_.reshape(-1),
                cues.scaler.scale_.reshape(-1),
                cues.weights,
                dist.center,
            ]
        ).astype(np.float32)
        if self.per_feature.shape[1] != forest.n_features:
            raise ValueError("the small-batch path needs the scaler's statistics per feature")
        self.clip = np.float32(cues.scaler.clip)
        self.log_compress = bool(cues.scaler.log_compress)
        self.dist = dist
        self.ref_t = dist._ref.T  # the same transposed view the general path multiplies by
        self.no_res = np.zeros(0, np.float32)
        self.labels = cues.reference_labels
        self.offsets = cues.offsets
        self.cue_weights = model.known_.weights
        self.entropy_used = bool(self.cue_weights[_ENTROPY] != 0.0)
        self.novel = _NovelConstants(model) if model.registry.novel_names else None

    def scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        z, p, novelty = self.known(x)
        return novelty, p, None if self.novel is None else self.novel.proba(z, p)

    def known(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(scaled samples, known-class probabilities, novelty scores): ``KnownModel.scores``."""
        if self.log_compress:  # RobustInputScaler._compress: log1p(|x|) with x's sign
            mag = np.abs(x)
            np.log1p(mag, out=mag)
        else:
            mag = x
        f, dist = self.forest, self.dist
        z, q, p, top, best = _scale_and_walk(
            x,
            mag,
            self.log_compress,
            self.per_feature,
            self.clip,
            f._nodes,
            f.roots,
            f.leaf_ptr,
            f.leaf_class,
            f.leaf_value,
            self.n_classes,
        )
        if dist.basis is None:  # exact distances: no subspace, no residuals
            proj, q_sq, ref_res = q, self.no_res, self.no_res
        else:
            proj, q_sq, ref_res = q @ dist.basis, _add(q * q, axis=1), dist._ref_res
        proj_sq = _add(proj * proj, axis=1)
        near = _near(proj @ self.ref_t, q_sq, proj_sq, dist._ref_sq, ref_res, self.labels, best)
        log_d = np.log(near)
        entropy = -_add(p * np.log(np.clip(p, 1e-12, None)), axis=1) if self.entropy_used else None
        cues = _cues(top, log_d, self.offsets, best, entropy, self.n_classes > 1)
        return z, p, cues @ self.cue_weights


class _NovelConstants:
    """What ``BestRecognizer._novel_from`` derives from the model alone, derived once."""

    def __init__(self, model: BestRecognizer) -> None:
        reg = model.registry
        self.has_attributes = model.has_attributes
        self.shot_temperature = float(model.shot_temperature)
        has = model.shot_has_
        self.any_shot = bool(has.any())
        self.shot_columns = np.flatnonzero(has)
        self.zsl_columns = np.flatnonzero(~has)
        # (L', K) prototypes; the general path multiplies by the transpose of this copy
        self.prototypes = (
            model.shot_prototypes_ if not self.has_attributes else model.shot_prototypes_[has]
        )
        if not self.has_attributes:
            return
        attrs = model.attributes_
        self.attr_weights_t = attrs._weights_t32
        self.attr_bias = attrs.bias
        self.fixed = np.flatnonzero(~np.isnan(attrs.constant))
        self.fixed_values = attrs.constant[self.fixed]
        # dap_log_scores' class-vector terms and prior term, as it computes them
        clip = float(model.dap_clip)
        self.dap_clip = clip
        present, absent = dap_class_terms(reg.novel_attributes)
        self.present_t, self.absent_t = present.T, absent.T
        q = np.clip(model.prior_, clip, 1 - clip)
        self.log_prior = (np.log(q) @ present.T + np.log1p(-q) @ absent.T)[None, :]
        self.sae_t, self.sae_temperature = None, 0.0
        if model.sae_ is not None:
            self.sae_t = np.asarray(model.sae_, np.float32).T
            vectors = np.asarray(impute(reg.novel_attributes, model.prior_), np.float64)
            self.unit_vectors_t = _unit(vectors).T
            self.sae_temperature = float(model.sae_temperature)

    def proba(self, z: np.ndarray, known_p: np.ndarray) -> np.ndarray:
        """``BestRecognizer._novel_from(z, known_p)``."""
        if not self.has_attributes:
            sim = _signatures(known_p) @ self.prototypes.T
            return _softmax_of_shifted(_shifted(sim, self.shot_temperature))
        # LinearAttributeModel.predict_proba, then dap_log_scores
        half = _half_logits(z @ self.attr_weights_t, self.attr_bias)
        p, minus_p = _attribute_clip(
            np.tanh(half), self.fixed, self.fixed_values, self.dap_clip, 1 - self.dap_clip
        )
        present, absent = np.log(p) @ self.present_t, np.log1p(minus_p) @ self.absent_t
        cosine = None
        if self.sae_t is not None:  # cosine_scores
            projected, squares = _widened_and_squared(z @ self.sae_t)
            cosine = _divide_by_norm(projected, _add(squares, axis=1)) @ self.unit_vectors_t
        shifted = _zsl_shifted(present, absent, self.log_prior, cosine, self.sae_temperature)
        p_zsl = _softmax_of_shifted(shifted)
        if not self.any_shot:
            return p_zsl
        sim = _signatures(known_p) @ self.prototypes.T
        e_shot = np.exp(_shifted(sim, self.shot_temperature))
        rest = _add(p_zsl[:, self.zsl_columns], axis=1)
        return _mix_shots(p_zsl, rest, e_shot, _add(e_shot, axis=1), self.shot_columns)


def _unit(m: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length, as ``cosine_scores`` does (np.linalg.norm's own steps)."""
    return _divide_by_norm(m, _add(m * m, axis=1))


def _softmax_of_shifted(shifted: np.ndarray) -> np.ndarray:
    """``attributes.softmax`` of logits already less their row maximum."""
    e = np.exp(shifted)
    return e / _add(e, axis=1, keepdims=True)


def _signatures(known_p: np.ndarray) -> np.ndarray:
    """``best.signatures`` of float64 posteriors."""
    return _unit(known_p)


# ------------------------------------------------------------------ compiled kernels
@njit(cache=True, nogil=True)
def _scale_and_walk(
    x,
    mag,
    log_compress,
    per_feature,
    clip,
    nodes,
    roots,
    leaf_ptr,
    leaf_class,
    leaf_value,
    n_classes,
):
    """RobustInputScaler.transform's exact steps after log1p, the centred feature-weighted
    query of ReferenceDistances._split, and FlatForest.predict_proba; per sample also the
    largest and second largest probability and the first class with the largest."""
    n, d = x.shape
    center, scale, feature_weights, dist_center = (
        per_feature[0],
        per_feature[1],
        per_feature[2],
        per_feature[3],
    )
    z = np.empty((n, d), np.float32)
    q = np.empty((n, d), np.float32)
    for i in range(n):
        for j in range(d):
            v = np.copysign(mag[i, j], x[i, j]) if log_compress else mag[i, j]
            v = (v - center[j]) / scale[j]
            v = min(max(v, -clip), clip)
            z[i, j] = v
            q[i, j] = v * feature_weights[j] - dist_center[j]
    p = np.zeros((n, n_classes))
    thresholds = nodes.view(np.float32)
    for i in range(n):
        _walk_trees(z[i], nodes, thresholds, roots, leaf_ptr, leaf_class, leaf_value, p[i])
    n_trees = np.float64(roots.shape[0])
    top = np.empty((n, 2))  # largest, second largest
    best = np.empty(n, np.int64)  # the first class with the largest
    for i in range(n):
        first, second, arg = -np.inf, -np.inf, 0
        for c in range(n_classes):
            v = p[i, c] / n_trees
            p[i, c] = v
            if v > first:
                first, second, arg = v, first, c
            elif v > second:
                second = v
        top[i, 0], top[i, 1], best[i] = first, second, arg
    return z, q, p, top, best


@njit(cache=True, nogil=True)
def _walk_trees(x, nodes, thresholds, roots, leaf_ptr, leaf_class, leaf_value, proba):
    """forest._walk for one sample: it takes a block of trees down together instead of a
    block of samples (independent load chains again), then adds the leaves' distributions
    in tree order, as _walk does, so the sums have the same bits."""
    at = np.empty(_TREES, np.int32)
    for lo in range(0, roots.shape[0], _TREES):
        hi = min(lo + _TREES, roots.shape[0])
        for k in range(hi - lo):
            at[k] = roots[lo + k]
        descending = True
        while descending:
            descending = False
            for k in range(hi - lo):
                node = at[k]
                f = nodes[node, 0]
                if f >= 0:
                    at[k] = nodes[node, 2 + (x[f] > thresholds[node, 1])]
                    descending = True
        for k in range(hi - lo):
            leaf = nodes[at[k], 2]
            for j in range(leaf_ptr[leaf], leaf_ptr[leaf + 1]):
                proba[leaf_class[j]] += leaf_value[j]


@njit(cache=True, nogil=True)
def _near(g, q_sq, proj_sq, ref_sq, ref_res, labels, best):
    """ReferenceDistances.nearest from the products ``g``, plus ForestCues.cues' epsilon:
    the residual norms sqrt(max(|q|^2 - |P q|^2, 0)) in float32 as ``_split`` takes them
    (none without a basis: ``q_sq`` empty)."""
    res = np.empty(q_sq.shape[0], np.float32)
    for i in range(q_sq.shape[0]):
        res[i] = np.sqrt(max(q_sq[i] - proj_sq[i], np.float32(0.0)))
    near = _nearest(g, proj_sq, ref_sq, res, ref_res, labels, best, _KNN)
    for i in range(near.shape[0]):
        for c in range(3):
            near[i, c] = near[i, c] + _EPS
    return near


@njit(cache=True, nogil=True)
def _cues(top, log_d, offsets, best, entropy, several):
    """ForestCues.cues' columns from the top probabilities and log distances."""
    n = top.shape[0]
    out = np.empty((n, 6))
    for i in range(n):
        gap = top[i, 0] - (top[i, 1] if several else 0.0)
        out[i, 0] = 1.0 - top[i, 0]
        out[i, 1] = 0.0 if entropy is None else entropy[i]
        out[i, 2] = -gap
        out[i, 3] = log_d[i, 0] - offsets[0]
        out[i, 4] = log_d[i, 1] - offsets[1]
        out[i, 5] = log_d[i, 2] - offsets[2 + best[i]]
    return out


@njit(cache=True, nogil=True)
def _divide_by_norm(m, sq):
    out = np.empty_like(m)
    for i in range(m.shape[0]):
        norm = max(np.sqrt(sq[i]), 1e-12)
        for j in range(m.shape[1]):
            out[i, j] = m[i, j] / norm
    return out


@njit(cache=True, nogil=True)
def _half_logits(products, bias):
    """0.5 x the attribute logits (float32 products to float64, plus the bias)."""
    out = np.empty((products.shape[0], products.shape[1]))
    for i in range(products.shape[0]):
        for j in range(products.shape[1]):
            out[i, j] = 0.5 * (np.float64(products[i, j]) + bias[j])
    return out


@njit(cache=True, nogil=True)
def _attribute_clip(tanh_half, fixed, fixed_values, lo, hi):
    """The sigmoid from tanh, the attributes constant over the known classes, DAP's clip;
    the clipped probabilities and their negatives."""
    p = np.empty_like(tanh_half)
    minus = np.empty_like(tanh_half)
    for i in range(p.shape[0]):
        for j in range(p.shape[1]):
            p[i, j] = 0.5 * (1.0 + tanh_half[i, j])
        for f in range(fixed.shape[0]):
            p[i, fixed[f]] = fixed_values[f]
        for j in range(p.shape[1]):
            v = min(max(p[i, j], lo), hi)
            p[i, j] = v
            minus[i, j] = -v
    return p, minus


@njit(cache=True, nogil=True)
def _widened_and_squared(m):
    """float32 ``m`` as float64, and its squares."""
    wide = np.empty((m.shape[0], m.shape[1]))
    squares = np.empty_like(wide)
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            v = np.float64(m[i, j])
            wide[i, j] = v
            squares[i, j] = v * v
    return wide, squares


@njit(cache=True, nogil=True)
def _zsl_shifted(present, absent, log_prior, cosine, temperature):
    """DAP's log scores (its two products) less the prior term, plus the autoencoder's
    weighted cosine, less each row's maximum (softmax's shift)."""
    out = np.empty_like(present)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            v = (present[i, j] + absent[i, j]) - log_prior[0, j]
            if cosine is not None:
                v = v + temperature * cosine[i, j]
            out[i, j] = v
    return _shift_rows(out)


@njit(cache=True, nogil=True)
def _shifted(sim, temperature):
    """sim / temperature less each row's maximum."""
    out = np.empty_like(sim)
    for i in range(sim.shape[0]):
        for j in range(sim.shape[1]):
            out[i, j] = sim[i, j] / temperature
    return _shift_rows(out)


@njit(cache=True, nogil=True)
def _shift_rows(x):
    for i in range(x.shape[0]):
        top = x[i, 0]
        for j in range(1, x.shape[1]):
            top = max(top, x[i, j])
        for j in range(x.shape[1]):
            x[i, j] = x[i, j] - top
    return x


@njit(cache=True, nogil=True)
def _mix_shots(p_zsl, rest, e_shot, e_sum, shot_columns):
    """Classes with one-shot samples share what the zero-shot-only classes leave, by their
    softmax (exponentials ``e_shot`` over their row sums ``e_sum``)."""
    out = p_zsl.copy()
    for i in range(out.shape[0]):
        for s in range(shot_columns.shape[0]):
            out[i, shot_columns[s]] = (1.0 - rest[i]) * (e_shot[i, s] / e_sum[i])
    return out
