"""Exploration bench (from 803466d): zero-shot alternatives to DAP, dev seeds only.

DAP multiplies per-attribute probabilities as if the attribute classifiers erred
independently and were calibrated on unseen objects. Neither holds: "soft",
"squishy" and "compressible" err together, and a classifier's scores on objects it
never saw are less extreme than on its training objects. The first two approaches
model both, learning from the known objects only; the last two change DAP's inputs:

- ``asg`` (attribute-score Gaussian): out-of-object attribute logits of the known
  training samples (group k-fold over objects, so each object is scored by
  classifiers that never saw it) are regressed on the objects' attribute vectors,
  s ≈ W a + b, and their residuals give a full covariance Σ (Ledoit-Wolf). A novel
  class z scores log N(s(x); W a^z + b, Σ). ``asg-diag``: the same with a diagonal Σ.
- ``flg`` (feature linear Gaussian): in the training samples' top principal
  subspace, class means are ridge-regressed on attribute vectors; a novel class is
  N(W a^z + b, Σ_within + Σ_mean), Σ_mean from the leave-one-class-out residuals of
  the regression (how far a predicted class mean misses a real one).
- ``twins<s>``: a novel class is scored by the forest's posterior on the known objects
  whose attribute vectors are close to its own (Hamming kernel of sharpness s).
- ``svm<C>``: DAP with one RBF-kernel SVM per attribute (Platt-scaled), as Lampert et al.
- ``znorm`` / ``zmean`` (be3c8fd): DAP scores minus each novel class's mean score (and
  divided by its spread) over known training samples scored out of object (hubness).
- ``lda<C>`` (be0c591): DAP on the shrinkage-LDA subspace of the known objects.
- ``sae<s|f><λ>`` (8e8eab5): the semantic autoencoder of Kodirov et al. (2017), matched
  in attribute space (``s``) or feature space (``f``). Seeds 1–2, 6 novel (DAP 0.446):
  alone 0.41–0.45 for every λ from 0.2 to 4000, × DAP 0.442–0.471 (s-space, rising with
  λ to 0.459–0.471 for λ 5–1000); 12 novel (DAP 0.267), 9 of those variants: × DAP
  0.268–0.276. ``saes400``
  (× DAP 0.466 / 0.273) was then fixed and run on untouched seeds 3–4: DAP 0.403 → 0.447
  at 6 novel (paired +0.044 ± 0.041, 10 splits won, 0 lost) and 0.234 → 0.251 at 12
  (+0.017 ± 0.021, 10 won, 2 lost). Adopted into ``best`` (``sae_lambda``).
- ``bag<B>`` (bb24ffa): DAP with each attribute's probability averaged over B logistic
  regressions, each fitted on a random 80 % of the known objects (an ensemble over object
  subsets). Seeds 1–2, 6 novel: bag20 alone 0.433, × DAP 0.446 (DAP 0.446); with the SAE
  (``saes400+bag20``, scores summed) 0.466 alone and 0.459 × DAP, against DAP × SAE's
  0.466. No gain; not adopted.

- ``saes<λ>@<T>`` (bb24ffa): the SAE's temperature T (10 in ``best``). Seeds 1–2, 6 novel,
  × DAP: T = 5 0.458, 10 0.466, 15 0.466, 20 0.464, 30 0.462. 10 stays.
- ``ksae<λ>@<γ>`` (bb24ffa): the SAE on 400 Nyström features of an RBF kernel (γ / D).
  Seeds 1–2, 6 novel: λ 100 / 400 / 1000 at γ 1 alone 0.403–0.405, × DAP 0.426; γ 0.3
  0.443 / 0.438; beside the linear SAE (``saes400+ksae400@1``) 0.439 / 0.440, against the
  linear SAE's 0.444 / 0.466. A non-linear map overfits the 54 objects; not adopted.

- ``dap-C<C>``, ``dap-k<clip>``, ``dap-p<exponent>``, ``dap-fisher`` (bb24ffa): DAP's own
  settings again, now beside the SAE (``+saes400``; alone / with the SAE). Seeds 1–2, 6 novel
  (DAP 0.446, DAP + SAE 0.466): C 0.03 / 0.3 / 1: 0.427 / 0.433 / 0.423, with the SAE 0.462 /
  0.451 / 0.430; clip 0.05 / 0.1: 0.431 / 0.407, with the SAE 0.456 / 0.447; inputs weighted by
  their Fisher ratio 0.451, with the SAE 0.447; the prior p(a) divided out with exponent 0 /
  0.5 (DAP: 1): 0.460 / 0.462, with the SAE 0.483 / 0.474. At 12 novel (DAP 0.267, DAP + SAE
  0.273) the prior exponents 0 / 0.5 give 0.237 / 0.266 alone and 0.260 / 0.273 with the SAE:
  what dropping the prior wins with 6 novel objects it loses with 12. Nothing adopted.

- ``ep-dap``, ``ep-sae`` (bb24ffa): one DAP or SAE per exploratory procedure (squeeze,
  hold, slide, move down), their scores summed: experts whose errors come from different
  touches. Seeds 1–2, 6 novel: alone 0.403 / 0.429, × DAP 0.423 / 0.452; ``ep-sae+saes400``
  × DAP 0.462 and ``ep-dap+ep-sae`` × DAP 0.454, against DAP × SAE's 0.466. Not adopted.

Approaches joined by ``+`` are summed (their posteriors multiplied) before scoring, so
``saes400+bag20`` with "× DAP" is the product of all three.

Each is reported alone and as a product with DAP (``best``'s zero-shot), on the
novel objects' held-out trials of development split seeds (never seed 0):

    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches twins0.5,twins1,twins2,twins4
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches svm0.3,svm1,svm3,svm10,svm30
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches znorm,zmean
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches lda0.01,lda0.1,lda1
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 \
        --approaches saes0.2,saes1,saes5,saes25,saes100,saes400,saes1000,saes4000,saef0.2,saef1,saef5
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 12 \
        --approaches saes1,saes5,saes25,saes100,saes400,saes1000,saes4000,saef1,saef5
    .venv/bin/python bench/research/explore_scorespace.py --seeds 3,4 --novel 6 --approaches saes400   # then --novel 12
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches saes400,bag20,saes400+bag20
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 \
        --approaches saes400@5,saes400,saes400@15,saes400@20,saes400@30
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 \
        --approaches saes400,ksae400@1,ksae400@0.3,ksae100@1,ksae1000@1,saes400+ksae400@1
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 --approaches saes400,dap-C0.03,\
dap-C0.03+saes400,dap-C0.3,dap-C0.3+saes400,dap-C1,dap-C1+saes400,dap-k0.05,dap-k0.05+saes400,\
dap-k0.1,dap-k0.1+saes400,dap-p0,dap-p0+saes400,dap-p0.5,dap-p0.5+saes400,dap-fisher,dap-fisher+saes400
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 12 \
        --approaches saes400,dap-p0,dap-p0+saes400,dap-p0.5,dap-p0.5+saes400
    .venv/bin/python bench/research/explore_scorespace.py --seeds 1,2 --novel 6 \
        --approaches saes400,ep-dap,ep-sae,ep-dap+saes400,ep-sae+saes400,ep-dap+ep-sae

``dap`` is plain DAP throughout: ``dev_splits`` fits ``best`` with ``sae_lambda`` 0.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from dev_splits import add_split_arguments, print_zsl_means, tiny, zsl_cases
from sklearn.covariance import LedoitWolf
from sklearn.model_selection import GroupKFold

from app.data.phac2 import load_phac2
from app.methods.attributes import LinearAttributeModel


def logits(p: np.ndarray, clip: float) -> np.ndarray:
    p = np.clip(p, clip, 1 - clip)
    return np.log(p) - np.log1p(-p)


def gaussian_scores(s: np.ndarray, means: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(N, L) log N(s; means_l, cov) up to a shared constant."""
    prec = np.linalg.pinv(cov)
    d = s[:, None, :] - means[None, :, :]
    return -0.5 * np.einsum("nld,de,nle->nl", d, prec, d)


def ridge(a: np.ndarray, t: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """t ≈ a @ W + b, ridge on centred data."""
    am, tm = a.mean(0), t.mean(0)
    ac = a - am
    w = np.linalg.solve(ac.T @ ac + alpha * np.eye(a.shape[1]), ac.T @ (t - tm))
    return w, tm - am @ w


def out_of_object_logits(z, y, targets, C, folds, clip):
    s = np.zeros(targets.shape)
    for fit, held in GroupKFold(folds).split(z, groups=y):
        model = LinearAttributeModel.fit(z[fit], targets[fit], C)
        s[held] = logits(model.predict_proba(z[held]), clip)
    return s


def asg(z, y, attrs, z_test, vectors, args, diagonal: bool):
    targets = attrs[y]
    s = out_of_object_logits(z, y, targets, args.C, args.folds, args.clip)
    keep = s.std(0) > 1e-6
    w, b = ridge(targets, s[:, keep], args.alpha)
    resid = s[:, keep] - (targets @ w + b)
    cov = np.diag(resid.var(0)) if diagonal else LedoitWolf().fit(resid).covariance_
    full = LinearAttributeModel.fit(z, targets, args.C)
    st = logits(full.predict_proba(z_test), args.clip)[:, keep]
    return gaussian_scores(st, vectors @ w + b, cov)


def flg(z, y, attrs, z_test, vectors, args):
    mean = z.mean(0)
    _, _, vt = np.linalg.svd(z - mean, full_matrices=False)
    basis = vt[: args.components].T
    p, pt = (z - mean) @ basis, (z_test - mean) @ basis
    k = attrs.shape[0]
    class_means = np.stack([p[y == c].mean(0) for c in range(k)])
    within = LedoitWolf().fit(p - class_means[y]).covariance_
    loo = np.zeros_like(class_means)
    for c in range(k):  # leave one class out: how far a predicted mean misses a real one
        others = np.arange(k) != c
        w, b = ridge(attrs[others], class_means[others], args.alpha)
        loo[c] = class_means[c] - (attrs[c] @ w + b)
    w, b = ridge(attrs, class_means, args.alpha)
    between = LedoitWolf().fit(loo).covariance_
    return gaussian_scores(pt, vectors @ w + b, within + between)


def svm_dap(z, y, attrs, z_test, vectors, C, args):
    """DAP as Lampert et al. ran it: one RBF-kernel SVM per attribute, Platt-scaled."""
    from sklearn.svm import SVC

    from app.methods.attributes import dap_log_scores

    targets = attrs[y] > 0.5
    p = np.tile(attrs.mean(0), (len(z_test), 1))
    for m in range(attrs.shape[1]):
        if targets[:, m].all() or not targets[:, m].any():
            continue
        svc = SVC(C=C, gamma="scale", probability=True, random_state=0).fit(z, targets[:, m])
        p[:, m] = svc.predict_proba(z_test)[:, 1]
    return dap_log_scores(p, vectors, attrs.mean(0), args.clip)


def class_norm(z, y, attrs, z_test, vectors, args, scale: bool):
    """DAP scores standardised per novel class by their spread on known objects the
    attribute classifiers never saw: some attribute vectors match many objects (hubs)."""
    from app.methods.attributes import dap_log_scores

    targets = attrs[y]
    prior = attrs.mean(0)
    held_scores = np.zeros((len(z), len(vectors)))
    for fit, held in GroupKFold(args.folds).split(z, groups=y):
        model = LinearAttributeModel.fit(z[fit], targets[fit], args.C)
        held_scores[held] = dap_log_scores(model.predict_proba(z[held]), vectors, prior, args.clip)
    full = LinearAttributeModel.fit(z, targets, args.C)
    scores = dap_log_scores(full.predict_proba(z_test), vectors, prior, args.clip)
    scores = scores - held_scores.mean(0)
    return scores / held_scores.std(0) if scale else scores


def lda_dap(z, y, attrs, z_test, vectors, C, args):
    """DAP on the known objects' discriminant subspace (shrinkage LDA): attribute
    classifiers see only directions that tell objects apart, not trial-to-trial noise."""
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    from app.methods.attributes import dap_log_scores

    lda = LinearDiscriminantAnalysis(solver="eigen", shrinkage="auto").fit(z, y)
    p, pt = lda.transform(z), lda.transform(z_test)
    scale = p.std(0)
    model = LinearAttributeModel.fit(p / scale, attrs[y], C)
    return dap_log_scores(model.predict_proba(pt / scale), vectors, attrs.mean(0), args.clip)


def sae(z, y, attrs, z_test, vectors, lam: float, space: str):
    """Semantic autoencoder (Kodirov et al., 2017): W maps features to attributes and Wᵀ
    maps back, min ‖X − WᵀS‖² + λ‖WX − S‖², closed form by a Sylvester equation. A test
    sample is matched to the novel classes by cosine, either as W x against their vectors
    (``space`` 's') or as x against Wᵀ a^z (``space`` 'f'); ×10 as a temperature."""
    from scipy.linalg import solve_sylvester

    x, a = z.T, attrs[y].T  # (D, N), (K, N)
    w = solve_sylvester(a @ a.T, lam * (x @ x.T), (1 + lam) * (a @ x.T))  # (K, D)
    unit = lambda m: m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)  # noqa: E731
    if space == "s":
        return 10 * unit(z_test @ w.T) @ unit(vectors).T
    return 10 * unit(z_test) @ unit(vectors @ w).T


def bagged_dap(z, y, attrs, z_test, vectors, bags: int, args, share: float = 0.8):
    """DAP whose attribute probabilities are averaged over ``bags`` classifiers, each fitted
    on the trials of a random ``share`` of the known objects: an ensemble over object
    subsets, so that no single object's quirks decide an attribute."""
    from app.methods.attributes import dap_log_scores

    rng = np.random.default_rng(0)
    classes = np.unique(y)
    p = 0.0
    for _ in range(bags):
        keep = np.isin(y, rng.choice(classes, int(round(share * len(classes))), replace=False))
        p = p + LinearAttributeModel.fit(z[keep], attrs[y[keep]], args.C).predict_proba(z_test)
    return dap_log_scores(p / bags, vectors, attrs.mean(0), args.clip)


def kernel_sae(z, y, attrs, z_test, vectors, lam: float, gamma: float, components: int = 400):
    """The SAE on an RBF kernel's Nyström features of the scaled inputs (γ relative to 1/D):
    a non-linear map from touch to attributes, regularised by the same reconstruction."""
    from sklearn.kernel_approximation import Nystroem

    phi = Nystroem(
        gamma=gamma / z.shape[1], n_components=min(components, len(z)), random_state=0
    ).fit(z)
    f, ft = phi.transform(z), phi.transform(z_test)
    mean, std = f.mean(0), f.std(0) + 1e-9
    return sae((f - mean) / std, y, attrs, (ft - mean) / std, vectors, lam, "s")


def dap_variant(z, y, attrs, z_test, vectors, C: float, clip: float, prior: float, fisher: bool):
    """DAP with another C, probability clip, prior exponent (1: divide by p(a) as DAP does,
    0: no prior) or, with ``fisher``, on inputs weighted by how well each tells the known
    objects apart (between- over within-object variance, as ``best``'s distances are)."""
    from app.methods.attributes import dap_log_scores
    from app.methods.known import fisher_weights

    if fisher:
        w = fisher_weights(z, y, int(y.max()) + 1)
        z, z_test = z * w, z_test * w
    p = LinearAttributeModel.fit(z, attrs[y], C).predict_proba(z_test)
    full = dap_log_scores(p, vectors, attrs.mean(0), clip)
    flat = dap_log_scores(
        p, vectors, np.full(attrs.shape[1], 0.5), clip
    )  # a flat prior adds nothing
    return prior * full + (1 - prior) * flat


def per_procedure(z, y, attrs, z_test, vectors, kind: str, args, procedures: int = 4):
    """The sum over exploratory procedures of one model per procedure (DAP or the SAE on that
    procedure's features alone): experts whose errors come from different touches."""
    from app.methods.attributes import dap_log_scores

    total = 0.0
    for part in np.split(np.arange(z.shape[1]), procedures):
        if kind == "sae":
            total = total + sae(z[:, part], y, attrs, z_test[:, part], vectors, 400, "s")
        else:
            p = LinearAttributeModel.fit(z[:, part], attrs[y], args.C).predict_proba(
                z_test[:, part]
            )
            total = total + dap_log_scores(p, vectors, attrs.mean(0), args.clip)
    return total


def twins(
    known_p: np.ndarray, attrs: np.ndarray, vectors: np.ndarray, sharpness: float
) -> np.ndarray:
    """log Σ_k p(k | x) exp(-sharpness · hamming(a^z, a^k)): a novel class feels like the
    known objects that people describe alike."""
    hamming = np.abs(vectors[:, None, :] - attrs[None, :, :]).sum(2)  # (L, K)
    kernel = np.exp(-sharpness * hamming)
    kernel /= kernel.sum(1, keepdims=True)
    return np.log(known_p @ kernel.T + 1e-12)


def one_approach(approach: str, case, args) -> np.ndarray:
    """The (N, novel classes) log-scores of one approach on one case."""
    z, zt, y, vectors = case.z, case.zt, case.train.labels, case.vectors
    attrs = case.train.class_attributes.astype(np.float64)
    if approach in ("asg", "asg-diag"):
        return asg(z, y, attrs, zt, vectors, args, approach == "asg-diag")
    elif approach == "flg":
        return flg(z, y, attrs, zt, vectors, args)
    elif approach in ("znorm", "zmean"):
        return class_norm(z, y, attrs, zt, vectors, args, approach == "znorm")
    elif approach.startswith("lda"):
        return lda_dap(z, y, attrs, zt, vectors, float(approach[3:] or 0.1), args)
    elif approach.startswith("svm"):
        return svm_dap(z, y, attrs, zt, vectors, float(approach[3:] or 1), args)
    elif approach.startswith("sae"):  # sae<s|f><λ>[@temperature], e.g. saes1, saef0.2, saes400@20
        lam, _, temperature = approach[4:].partition("@")
        return (
            sae(z, y, attrs, zt, vectors, float(lam or 1), approach[3])
            * float(temperature or 10)
            / 10
        )
    elif approach.startswith("ksae"):  # ksae<λ>[@γ], e.g. ksae400@1
        lam, _, gamma = approach[4:].partition("@")
        return kernel_sae(z, y, attrs, zt, vectors, float(lam or 400), float(gamma or 1))
    elif approach.startswith("dap-"):  # dap-C<C>, dap-k<clip>, dap-p<prior exponent>, dap-fisher
        options = {"C": args.C, "k": args.clip, "p": 1.0}
        key = approach[4]
        if approach != "dap-fisher":
            options[key] = float(approach[5:])
        return dap_variant(
            z,
            y,
            attrs,
            zt,
            vectors,
            options["C"],
            options["k"],
            options["p"],
            approach == "dap-fisher",
        )
    elif approach in ("ep-dap", "ep-sae"):
        return per_procedure(z, y, attrs, zt, vectors, approach[3:], args)
    elif approach.startswith("twins"):
        return twins(case.cues.proba(zt), attrs, vectors, float(approach[5:] or 2))
    elif approach.startswith("bag"):  # bag<bags>, e.g. bag20
        return bagged_dap(z, y, attrs, zt, vectors, int(approach[3:] or 20), args)
    raise SystemExit(f"unknown approach {approach!r}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_split_arguments(p)
    p.add_argument("--approaches", default="asg,asg-diag,flg")
    p.add_argument("--C", type=float, default=0.1, help="attribute classifiers' C (best's)")
    p.add_argument("--clip", type=float, default=0.02, help="probability clip (best's)")
    p.add_argument("--folds", type=int, default=9, help="object folds for out-of-object logits")
    p.add_argument("--alpha", type=float, default=1.0, help="ridge penalty")
    p.add_argument("--components", type=int, default=32, help="flg: principal components")
    args = tiny(p.parse_args(), folds=2)
    data = load_phac2(args.data)
    cases = []
    for case in zsl_cases(data, args):
        for combo in args.approaches.split(","):
            scores = sum(one_approach(approach, case, args) for approach in combo.split("+"))
            case.record(combo, scores)
        case.finish()
        cases.append(case)
    print_zsl_means(cases, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
