"""``best``'s scores for a few samples at a time, bit-identical to the general path.

For one sample the general path (``KnownModel.scores`` and ``BestRecognizer._novel_from``)
costs several times its batch-amortised cost per sample: dozens of numpy calls on tiny
arrays, each paying its call overhead, plus constants recomputed on every call. This path:

- computes the model's constants once (``ScoringConstants.of``, per fitted model and novel
  part, through the parts' public methods; the scorer reads only that frozen object): DAP's
  prior term, the unit attribute vectors, the one-shot prototypes, the attribute model's
  fixed columns;
- fuses every step whose bits IEEE or numpy define into five compiled kernels, each run
  between two rounds of the numpy calls that must stay: the exact element-wise steps
  (+ - * /, min, max, sqrt, copysign: IEEE gives the same bits in any order of
  elements), the forest walk (``forest.walk_trees``: one sample walks a block of trees at
  once, independent load chains; the leaves are summed in tree order), and every sum
  along an axis, which ``_row_sum`` adds in numpy's own order (its pairwise summation: 8
  accumulators up to 128 elements, halves above; ``tests/methods/test_small_batch.py``
  checks it against ``np.add.reduce``);
- leaves to numpy exactly what the general path does with numpy and no order of IEEE
  operations defines: every transcendental function (log, log1p, exp, tanh: numpy's SIMD
  versions need not round like libm) and every matrix product (BLAS: a 1-row product
  takes gemv, more rows gemm, and each kernel adds in its own order), called on arrays of
  the same shapes, dtypes and memory layout, so their bits are the general path's;
- allocates the arrays the kernels fill in Python (a compiled function that returns an
  array pays more to hand it back than ``np.empty`` costs), for one sample once per thread,
  and passes each kernel as few arguments as it can (each one costs the dispatcher time to
  check; the scalars go in one array);
- calls numpy's exp once for both softmaxes (the zero-shot and the one-shot logits side by
  side in one contiguous array: numpy rounds each element of a contiguous array alike,
  wherever it lies).

What bit-identity keeps out of the kernels: fusing the two 960-wide products with ``z``
into one (``z`` times both matrices side by side) would change which BLAS kernel computes
each column (the attribute matrix is C-ordered, gemv "N"; the autoencoder's a transposed
view, gemv "T"), and merging DAP's two 19 x 6 products, the cosine's and the signatures'
would change BLAS's order of additions; float32 log1p, tanh, log and exp have SIMD
versions in numpy (SVML on AVX-512) that libm, which the kernels would call, need not
match.

With an index over the reference samples (``best``'s ``approximate_above``), the scorer
computes the queries' coordinates in a kernel and hands them to the index's own search
(``ReferenceDistances.nearest_to_points``, which the general path calls too): comparing a
query with every reference sample there would cost milliseconds at 30,000 objects.

A cue whose weight is 0 in the novelty score (the entropy, in ``best``) is not computed:
its product with 0 adds nothing to the weighted sum.
"""

from __future__ import annotations

from dataclasses import dataclass
from threading import get_ident
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from app.methods.attributes import dap_class_terms, impute
from app.methods.forest import walk_trees
from app.methods.known import CUES, DISTANCE_EPS, KNN, nearest_from_products

if TYPE_CHECKING:
    from app.methods.best import BestRecognizer
    from app.methods.known import ReferenceDistances

_add = np.add.reduce
_ENTROPY = CUES.index("entropy")
_BLOCK = 128  # numpy's pairwise sum adds up to this many elements in one block
_NONE64 = np.zeros((0, 0))  # an array a kernel is given for a part the model lacks
_NONE32 = np.zeros((0, 0), np.float32)
_NO_ROWS = np.zeros(0)
# ScoringConstants.settings: the scaler's clip, whether it log-compresses, whether there are
# several known classes, the one-shot and autoencoder temperatures, DAP's clip bounds, the
# neighbours of the knn cue and the epsilon added to distances before their log
(
    _CLIP,
    _LOG_COMPRESS,
    _SEVERAL,
    _SHOT_TEMPERATURE,
    _SAE_TEMPERATURE,
    _DAP_LO,
    _DAP_HI,
    _KNN,
    _EPS,
) = range(9)
_SETTINGS = 9


@dataclass(frozen=True, eq=False)
class NovelConstants:
    """What ``BestRecognizer._novel_from`` derives from the model alone; an array for a part
    the model lacks (attributes, an autoencoder) is empty."""

    n_novel: int
    has_attributes: bool
    shot_temperature: float
    any_shot: bool
    shot_columns: np.ndarray  # the novel classes with one-shot samples
    zsl_columns: np.ndarray  # the others
    prototypes_t: np.ndarray  # (K, L') one-shot prototypes, transposed as the general path
    n_attributes: int
    attr_weights_t: np.ndarray  # (D, M) float32, LinearAttributeModel.weights_t32
    attr_bias: np.ndarray
    fixed: np.ndarray  # the attributes constant over the known classes, and their values
    fixed_values: np.ndarray
    dap_clip: float
    present_t: np.ndarray  # dap_class_terms' two matrices, transposed
    absent_t: np.ndarray
    log_prior: np.ndarray  # (1, L) DAP's prior term
    sae_t: np.ndarray | None  # (D, M) float32 autoencoder, None without one
    unit_vectors_t: np.ndarray  # (M, L) unit attribute vectors for the cosine
    sae_temperature: float

    @classmethod
    def of(cls, model: BestRecognizer) -> NovelConstants:
        reg = model.registry
        has_attributes = model.has_attributes
        has = model.shot_has_
        # (L', K) prototypes; the general path multiplies by the transpose of this copy
        prototypes = model.shot_prototypes_ if not has_attributes else model.shot_prototypes_[has]
        out = dict(
            n_novel=len(reg.novel_names),
            has_attributes=has_attributes,
            shot_temperature=float(model.shot_temperature),
            any_shot=bool(has.any()),
            shot_columns=np.flatnonzero(has),
            zsl_columns=np.flatnonzero(~has),
            prototypes_t=prototypes.T,
            n_attributes=0,
            attr_weights_t=_NONE32,
            attr_bias=_NO_ROWS,
            fixed=np.zeros(0, np.int64),
            fixed_values=_NO_ROWS,
            dap_clip=0.0,
            present_t=_NONE64,
            absent_t=_NONE64,
            log_prior=_NONE64,
            sae_t=None,
            unit_vectors_t=_NONE64,
            sae_temperature=0.0,
        )
        if has_attributes:
            attrs = model.attributes_
            fixed = np.flatnonzero(~np.isnan(attrs.constant))
            # dap_log_scores' class-vector terms and prior term, as it computes them
            clip = float(model.dap_clip)
            present, absent = dap_class_terms(reg.novel_attributes)
            q = np.clip(model.prior_, clip, 1 - clip)
            out.update(
                n_attributes=len(attrs.bias),
                attr_weights_t=attrs.weights_t32,
                attr_bias=attrs.bias,
                fixed=fixed,
                fixed_values=attrs.constant[fixed],
                dap_clip=clip,
                present_t=present.T,
                absent_t=absent.T,
                log_prior=(np.log(q) @ present.T + np.log1p(-q) @ absent.T)[None, :],
            )
            if model.sae_ is not None:
                vectors = np.asarray(impute(reg.novel_attributes, model.prior_), np.float64)
                out.update(
                    sae_t=np.asarray(model.sae_, np.float32).T,
                    unit_vectors_t=_unit(vectors).T,
                    sae_temperature=float(model.sae_temperature),
                )
        return cls(**out)


@dataclass(frozen=True, eq=False)
class ScoringConstants:
    """Everything ``SmallBatchScorer`` reads of a fitted ``best``, taken once through the
    parts' public methods (``FlatForest.walk_arrays``, ``ReferenceDistances.reference_terms``,
    ``LinearAttributeModel.weights_t32``, the scaler's fitted statistics): the scorer reads
    nothing else of the model. The arrays are the parts' own, read and never written; a
    model changed by enrolment builds new constants (``BestRecognizer`` drops its scorer)."""

    n_classes: int
    # per feature: the scaler's centre and scale, the distance weights, the distance centre
    # (one float32 array: each argument of a compiled call costs time to check)
    per_feature: np.ndarray
    settings: np.ndarray  # the kernels' scalars in one array, indexed by _CLIP ... _EPS
    log_compress: bool
    walk: tuple[np.ndarray, ...]  # FlatForest.walk_arrays()
    basis: np.ndarray | None  # the distances' subspace, None when exact
    # exact search: ReferenceDistances.reference_terms(); through an index: empty, and the
    # distances whose ``nearest_to_points`` searches it
    ref_t: np.ndarray
    ref_sq: np.ndarray
    ref_res: np.ndarray
    indexed: ReferenceDistances | None
    labels: np.ndarray  # the reference samples' classes
    offsets: np.ndarray  # the log-distance cues' offsets
    cue_weights: np.ndarray
    entropy_used: bool  # a cue of weight 0 is not computed
    novel: NovelConstants | None  # None without novel classes

    @classmethod
    def of(cls, model: BestRecognizer) -> ScoringConstants:
        cues = model.known_.cues_model
        forest, dist, scaler = cues.forest, cues.distances, cues.scaler
        per_feature = np.stack(
            [scaler.center_.reshape(-1), scaler.scale_.reshape(-1), cues.weights, dist.center]
        ).astype(np.float32)
        if per_feature.shape[1] != forest.n_features:
            raise ValueError("the small-batch path needs the scaler's statistics per feature")
        cue_weights = model.known_.weights
        novel = NovelConstants.of(model) if model.registry.novel_names else None
        settings = np.zeros(_SETTINGS)
        settings[_CLIP] = scaler.clip
        settings[_LOG_COMPRESS] = bool(scaler.log_compress)
        settings[_SEVERAL] = forest.n_classes > 1
        settings[_KNN] = KNN
        settings[_EPS] = DISTANCE_EPS
        if novel is not None:
            settings[_SHOT_TEMPERATURE] = novel.shot_temperature
            if novel.has_attributes:
                settings[_DAP_LO], settings[_DAP_HI] = novel.dap_clip, 1 - novel.dap_clip
                settings[_SAE_TEMPERATURE] = novel.sae_temperature
        if dist.index is None:
            ref_t, ref_sq, ref_res = dist.reference_terms()
        else:
            ref_t, ref_sq, ref_res = _NONE32, np.zeros(0, np.float32), np.zeros(0, np.float32)
        return cls(
            n_classes=forest.n_classes,
            per_feature=per_feature,
            settings=settings,
            log_compress=bool(scaler.log_compress),
            walk=forest.walk_arrays(),
            basis=dist.basis,
            ref_t=ref_t,
            ref_sq=ref_sq,
            ref_res=ref_res,
            indexed=None if dist.index is None else dist,
            labels=cues.reference_labels,
            offsets=cues.offsets,
            cue_weights=cue_weights,
            entropy_used=bool(cue_weights[_ENTROPY] != 0.0),
            novel=novel,
        )


class SmallBatchScorer:
    """(novelty scores, known probabilities, novel probabilities) of flat float32 samples,
    as ``BestRecognizer._all_scores`` computes them, from a model's ``ScoringConstants``."""

    def __init__(self, constants: ScoringConstants) -> None:
        self.constants = constants
        # one sample's intermediate arrays, one set per thread: allocating them anew cost
        # as much as a kernel (the arrays returned are new on every call)
        self._one: dict[int, tuple[np.ndarray, ...]] = {}

    def _buffers(self, n: int) -> tuple[np.ndarray, ...]:
        """The intermediate arrays of ``n`` samples; an array for a part the model lacks
        is empty."""
        c = self.constants
        d, nv = c.per_feature.shape[1], c.novel
        z, q = np.empty((n, d), np.float32), np.empty((n, d), np.float32)
        top, near, cues = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 6))
        if nv is None:
            return z, q, top, near, cues
        m = nv.n_attributes
        sig = np.empty((n, c.n_classes)) if nv.any_shot else _NONE64
        half, minus, unit = _NONE64, _NONE64, _NONE64
        if nv.has_attributes:
            half, minus = np.empty((n, m)), np.empty((n, m))
            if nv.sae_t is not None:
                unit = np.empty((n, m))
        zsl = nv.n_novel if nv.has_attributes else 0
        shifted = np.empty((n, zsl + len(nv.shot_columns)))
        return z, q, top, near, cues, sig, half, minus, unit, shifted

    def scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        c = self.constants
        n = len(x)
        if n == 1:
            buffers = self._one.get(get_ident())
            if buffers is None:
                buffers = self._one[get_ident()] = self._buffers(1)
        else:
            buffers = self._buffers(n)
        z, q, top, near, cues = buffers[:5]
        if c.log_compress:  # RobustInputScaler._compress: log1p(|x|) with x's sign
            mag = np.abs(x)
            np.log1p(mag, out=mag)
        else:
            mag = x
        p = np.empty((n, c.n_classes))
        _scale_and_walk(x, mag, c.per_feature, c.settings, *c.walk, z, q, p, top)
        proj = q if c.basis is None else q @ c.basis
        entropy = _NO_ROWS
        if c.entropy_used:
            entropy = -_add(p * np.log(np.clip(p, 1e-12, None)), axis=1)
        nv = c.novel
        self._nearest(q, proj, top, near)
        if nv is None:
            _cues(top, np.log(near), c.offsets, entropy, c.settings, cues)
            return cues @ c.cue_weights, p, None
        # BestRecognizer._novel_from: LinearAttributeModel.predict_proba, dap_log_scores,
        # cosine_scores, the softmaxes and the one-shot mix
        sig, half, minus, unit, shifted = buffers[5:]
        attr, sae = _NONE32, _NONE32
        if nv.has_attributes:
            attr = z @ nv.attr_weights_t
            if nv.sae_t is not None:
                sae = z @ nv.sae_t
        _novel_inputs(p, attr, nv.attr_bias, half, sae, unit, sig)
        log_d = np.log(near)
        sim = sig @ nv.prototypes_t if nv.any_shot else _NONE64
        present, absent, cosine = _NONE64, _NONE64, _NONE64
        if nv.has_attributes:
            t = np.tanh(half)
            _attribute_clip(t, nv.fixed, nv.fixed_values, c.settings, minus)
            present, absent = np.log(t) @ nv.present_t, np.log1p(minus) @ nv.absent_t
            if nv.sae_t is not None:
                cosine = unit @ nv.unit_vectors_t
        _cues_and_shifts(
            top, log_d, c.offsets, entropy, c.settings, cues, present, absent,
            nv.log_prior, cosine, sim, shifted,
        )  # fmt: skip
        novelty = cues @ c.cue_weights
        out = np.empty((n, nv.n_novel))
        _mix(np.exp(shifted), nv.zsl_columns, nv.shot_columns, out)
        return novelty, p, out

    def _nearest(self, q: np.ndarray, proj: np.ndarray, top: np.ndarray, near: np.ndarray):
        """ReferenceDistances.nearest plus ForestCues.cues' epsilon, into ``near``: from the
        products with every reference sample (exact search), or through the index from the
        queries' coordinates, which ``_points`` computes as ``coordinates`` does."""
        c = self.constants
        if c.indexed is None:
            g = proj @ c.ref_t
            _near(q, proj, g, c.ref_sq, c.ref_res, c.labels, top, c.settings, near)
            return
        with_res = c.basis is not None
        points = np.empty((len(q), proj.shape[1] + with_res), np.float32)
        _points(q, proj, with_res, points)
        near[:] = c.indexed.nearest_to_points(points, c.labels, top[:, 2].astype(np.int64))
        near += c.settings[_EPS]


def _unit(m: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length, as ``cosine_scores`` does (np.linalg.norm's own steps)."""
    norm = np.maximum(np.sqrt(_add(m * m, axis=1, keepdims=True)), 1e-12)
    return m / norm


# ------------------------------------------------------------------ compiled kernels
@njit(cache=True, nogil=True, error_model="numpy")
def _row_sum(a, zero):
    """``np.add.reduce`` of a contiguous row ``a`` in its dtype (``zero`` of that dtype): the
    reduction starts from 0, its identity, and adds numpy's pairwise sum of the row, up to
    128 elements by ``_pairwise_block``, above that the sum of its two halves (the first a
    multiple of 8), each split again. The halves are walked with a stack, not by recursion
    (a recursive kernel loaded from numba's cache crashes)."""
    n = a.shape[0]
    if n <= _BLOCK:
        return zero + _pairwise_block(a, 0, n, zero)
    seg_lo = np.empty(192, np.int64)  # pending segments: 2 per level of at most 64 levels
    seg_n = np.empty(192, np.int64)
    seg_join = np.empty(192, np.bool_)  # "add the last two sums" rather than a segment
    sums = np.full(66, zero)
    seg_lo[0], seg_n[0], seg_join[0] = 0, n, False
    pending, done = 1, 0
    while pending > 0:
        pending -= 1
        lo, m = seg_lo[pending], seg_n[pending]
        if seg_join[pending]:
            done -= 1
            sums[done - 1] = sums[done - 1] + sums[done]
        elif m <= _BLOCK:
            sums[done] = _pairwise_block(a, lo, m, zero)
            done += 1
        else:
            half = m // 2
            half -= half % 8
            seg_lo[pending], seg_n[pending], seg_join[pending] = lo, m, True
            seg_lo[pending + 1], seg_n[pending + 1] = lo + half, m - half
            seg_lo[pending + 2], seg_n[pending + 2] = lo, half
            seg_join[pending + 1] = seg_join[pending + 2] = False
            pending += 3  # the first half on top: its sum comes first
    return zero + sums[0]


@njit(cache=True, nogil=True, error_model="numpy")
def _pairwise_block(a, lo, n, zero):
    """numpy's pairwise sum of a[lo : lo + n], n <= 128: below 8 elements one by one; else
    in 8 accumulators, combined as a tree, then the rest one by one."""
    if n < 8:
        res = zero
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i, end = lo + 8, lo + n - n % 8
    while i < end:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < lo + n:
        res += a[i]
        i += 1
    return res


@njit(cache=True, nogil=True, error_model="numpy")
def _scale_and_walk(
    x,
    mag,
    per_feature,
    settings,
    nodes,
    after,
    roots,
    mixed_ptr,
    mixed_class,
    mixed_value,
    z,
    q,
    p,
    top,
):
    """RobustInputScaler.transform's exact steps after log1p (into ``z``), the centred
    feature-weighted query of ReferenceDistances._split (``q``), FlatForest.predict_proba
    (``p``); per sample also the largest and second largest probability and the first class
    with the largest (``top``)."""
    n, d = x.shape
    clip, log_compress = np.float32(settings[_CLIP]), settings[_LOG_COMPRESS] != 0.0
    center, scale, feature_weights, dist_center = (
        per_feature[0],
        per_feature[1],
        per_feature[2],
        per_feature[3],
    )
    for i in range(n):
        for j in range(d):
            v = np.copysign(mag[i, j], x[i, j]) if log_compress else mag[i, j]
            v = (v - center[j]) / scale[j]
            v = min(max(v, -clip), clip)
            z[i, j] = v
            q[i, j] = v * feature_weights[j] - dist_center[j]
    p[:] = 0.0
    thresholds = nodes.view(np.float32)
    no_leaves = np.zeros((0, 0), np.int32)
    for i in range(n):
        walk_trees(
            z, i, nodes, thresholds, after, roots, mixed_ptr, mixed_class, mixed_value, no_leaves, p
        )
    n_trees = np.float64(roots.shape[0])
    for i in range(n):
        # the classes no tree reached (all but a few hundred of 30,000) stay 0, as 0 /
        # n_trees is, and rank below every reached one (each tree reaches some): they are
        # skipped, and only count as the second largest (0) where one class alone was
        first, second, arg, unreached = -np.inf, -np.inf, 0, False
        for c in range(p.shape[1]):
            v = p[i, c]
            if v == 0.0:
                unreached = True
                continue
            v = v / n_trees
            p[i, c] = v
            if v > first:
                first, second, arg = v, first, c
            elif v > second:
                second = v
        if unreached:
            second = max(second, 0.0)
        top[i, 0], top[i, 1], top[i, 2] = first, second, arg


@njit(cache=True, nogil=True, error_model="numpy")
def _norms(q, proj, i, squares, residual):
    """Of query ``i``: |P q|^2 and, with ``residual``, the residual norm
    sqrt(max(|q|^2 - |P q|^2, 0)) (else 0), in float32 as ``_split`` takes them."""
    zero = np.float32(0.0)
    for j in range(proj.shape[1]):
        squares[j] = proj[i, j] * proj[i, j]
    proj_sq = _row_sum(squares[: proj.shape[1]], zero)
    if not residual:
        return proj_sq, zero
    for j in range(q.shape[1]):
        squares[j] = q[i, j] * q[i, j]
    return proj_sq, np.sqrt(max(_row_sum(squares, zero) - proj_sq, zero))


@njit(cache=True, nogil=True, error_model="numpy")
def _points(q, proj, residual, out):
    """ReferenceDistances.coordinates: the projections, then (with ``residual``) the
    residual norms."""
    squares = np.empty(q.shape[1], np.float32)
    k = proj.shape[1]
    for i in range(q.shape[0]):
        for j in range(k):
            out[i, j] = proj[i, j]
        if residual:
            out[i, k] = _norms(q, proj, i, squares, True)[1]


@njit(cache=True, nogil=True, error_model="numpy")
def _near(q, proj, g, ref_sq, ref_res, labels, top, settings, near):
    """ReferenceDistances.nearest from the products ``g``, plus ForestCues.cues' epsilon
    (into ``near``), with |P q|^2 and, with a basis (``ref_res`` not empty), the residual
    norms (``_norms``)."""
    n = q.shape[0]
    proj_sq = np.empty(n, np.float32)
    res = np.empty(n if ref_res.shape[0] > 0 else 0, np.float32)
    squares = np.empty(q.shape[1], np.float32)
    for i in range(n):
        proj_sq[i], r = _norms(q, proj, i, squares, res.shape[0] > 0)
        if res.shape[0] > 0:
            res[i] = r
    best = np.empty(n, np.int64)
    for i in range(n):
        best[i] = np.int64(top[i, 2])
    knn, eps = np.int64(settings[_KNN]), settings[_EPS]
    no_groups = np.zeros(0, np.int64)
    found = nearest_from_products(
        g, proj_sq, ref_sq, res, ref_res, labels, best, knn, no_groups, no_groups
    )
    for i in range(n):
        for c in range(3):
            near[i, c] = found[i, c] + eps


@njit(cache=True, nogil=True, error_model="numpy")
def _unit_rows(m, out):
    """m's rows (float64 values) over max(their norm, 1e-12), as np.linalg.norm and
    signatures / cosine_scores compute them."""
    squares = np.empty(m.shape[1])
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            v = np.float64(m[i, j])
            squares[j] = v * v
        norm = max(np.sqrt(_row_sum(squares, 0.0)), 1e-12)
        for j in range(m.shape[1]):
            out[i, j] = np.float64(m[i, j]) / norm


@njit(cache=True, nogil=True, error_model="numpy")
def _novel_inputs(p, attr, bias, half, sae, unit, sig):
    """0.5 x the attribute logits (float32 products ``attr`` to float64, plus the
    bias) for the sigmoid by tanh; the autoencoder's projections ``sae`` as float64 over
    their norms; the signatures of the known-class posteriors (``best.signatures``). An
    empty output is a part the model lacks."""
    for i in range(half.shape[0]):
        for j in range(half.shape[1]):
            half[i, j] = 0.5 * (np.float64(attr[i, j]) + bias[j])
    if unit.shape[0] > 0:
        _unit_rows(sae, unit)
    if sig.shape[0] > 0:
        _unit_rows(p, sig)


@njit(cache=True, nogil=True, error_model="numpy")
def _cues(top, log_d, offsets, entropy, settings, out):
    """ForestCues.cues' columns from the top probabilities and log distances (the entropy's
    column 0 where it is not computed: ``entropy`` empty)."""
    several = settings[_SEVERAL] != 0.0
    for i in range(top.shape[0]):
        gap = top[i, 0] - (top[i, 1] if several else 0.0)
        out[i, 0] = 1.0 - top[i, 0]
        out[i, 1] = entropy[i] if entropy.shape[0] > 0 else 0.0
        out[i, 2] = -gap
        out[i, 3] = log_d[i, 0] - offsets[0]
        out[i, 4] = log_d[i, 1] - offsets[1]
        out[i, 5] = log_d[i, 2] - offsets[2 + np.int64(top[i, 2])]


@njit(cache=True, nogil=True, error_model="numpy")
def _attribute_clip(p, fixed, fixed_values, settings, minus):
    """In place, tanh(half logit) to the sigmoid, the attributes constant over the known
    classes, DAP's clip; their negatives into ``minus``."""
    lo, hi = settings[_DAP_LO], settings[_DAP_HI]
    for i in range(p.shape[0]):
        for j in range(p.shape[1]):
            p[i, j] = 0.5 * (1.0 + p[i, j])
        for f in range(fixed.shape[0]):
            p[i, fixed[f]] = fixed_values[f]
        for j in range(p.shape[1]):
            v = min(max(p[i, j], lo), hi)
            p[i, j] = v
            minus[i, j] = -v


@njit(cache=True, nogil=True, error_model="numpy")
def _cues_and_shifts(
    top, log_d, offsets, entropy, settings, cues, present, absent, log_prior, cosine, sim, out
):
    """``_cues``; then, into ``out``'s first columns (as many as ``present`` has), DAP's log
    scores (its two products) less the prior term, plus the autoencoder's weighted cosine
    (``cosine`` not empty), and into the rest sim / shot temperature; each part less its
    row's maximum (softmax's shift)."""
    _cues(top, log_d, offsets, entropy, settings, cues)
    zsl = out[:, : present.shape[1]]
    for i in range(present.shape[0]):
        for j in range(present.shape[1]):
            v = (present[i, j] + absent[i, j]) - log_prior[0, j]
            if cosine.shape[0] > 0:
                v = v + settings[_SAE_TEMPERATURE] * cosine[i, j]
            zsl[i, j] = v
    _shift_rows(zsl)
    shot = out[:, present.shape[1] :]
    for i in range(sim.shape[0]):
        for j in range(sim.shape[1]):
            shot[i, j] = sim[i, j] / settings[_SHOT_TEMPERATURE]
    _shift_rows(shot)


@njit(cache=True, nogil=True, error_model="numpy")
def _shift_rows(x):
    if x.shape[1] == 0:
        return
    for i in range(x.shape[0]):
        top = x[i, 0]
        for j in range(1, x.shape[1]):
            top = max(top, x[i, j])
        for j in range(x.shape[1]):
            x[i, j] = x[i, j] - top


@njit(cache=True, nogil=True, error_model="numpy")
def _mix(e, zsl_columns, shot_columns, out):
    """From the exponentials ``e`` of ``_cues_and_shifts``' two parts: the zero-shot softmax
    (none without attributes: ``e`` has only the one-shot part), then the classes with
    one-shot samples share what the zero-shot-only classes leave, by their softmax."""
    n_zsl = e.shape[1] - shot_columns.shape[0]
    rest_of = np.empty(zsl_columns.shape[0])
    for i in range(out.shape[0]):
        rest = 0.0
        if n_zsl > 0:
            total = _row_sum(e[i, :n_zsl], 0.0)
            for j in range(n_zsl):
                out[i, j] = e[i, j] / total
            for j in range(zsl_columns.shape[0]):
                rest_of[j] = out[i, zsl_columns[j]]
            rest = _row_sum(rest_of, 0.0)
        if shot_columns.shape[0] > 0:
            total = _row_sum(e[i, n_zsl:], 0.0)
            for s in range(shot_columns.shape[0]):
                out[i, shot_columns[s]] = (1.0 - rest) * (e[i, n_zsl + s] / total)
