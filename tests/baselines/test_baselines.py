"""Baselines: each beats chance on novel classes on simulated data under the full protocol;
their parts on hand-made cases; bad input and hyper-parameters; evaluation-only bundles."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression

from app.baselines.dap import DAPRecognizer, dap_log_scores, fit_logistic
from app.baselines.eszsl import ESZSLRecognizer, eszsl_fit, signatures
from app.baselines.extra_trees import ExtraTreesRecognizer
from app.data.simulator import simulate_dataset
from app.evaluation.protocol import FIGURES
from app.framework import bundle
from app.framework.errors import FrameworkError, InputShapeError, NonFiniteInputError
from app.framework.registry import make_method
from tests.simulated_protocol import N_NOVEL, small_protocol

BASELINES = ["extratrees", "dap", "eszsl"]
FAST = {  # fewer trees than the defaults, to keep the suite fast
    "extratrees": {"n_estimators": 60, "attribute_estimators": 60},
    "dap": {"n_estimators": 60, "C": 0.1},
    "eszsl": {"n_estimators": 60},
}


@pytest.fixture(scope="module")
def protocol_results():
    return small_protocol(BASELINES, 3, FAST)


@pytest.mark.parametrize("method", BASELINES)
def test_beats_chance_on_novel_classes(protocol_results, method):
    mean = protocol_results["methods"][method]["mean"]
    chance = 1 / N_NOVEL
    assert mean["zsl"] >= chance + 0.12, mean
    assert mean["osl"] >= chance + 0.3, mean
    assert mean["gzsl_unseen"] > chance / 2, mean
    assert mean["known_acc"] >= 0.8, mean
    assert mean["nd_auroc"] >= 0.7, mean
    for f in FIGURES:  # every figure of the protocol, in [0, 1]
        assert 0.0 <= mean[f] <= 1.0, f


@pytest.fixture(scope="module")
def small():
    return simulate_dataset(n_objects=12, trials_per_object=4, seed=2)


@pytest.fixture(scope="module")
def fitted(small):
    return {m: make_method(m, **FAST[m]).fit(small) for m in BASELINES}


@pytest.mark.parametrize("method", BASELINES)
def test_interface_shapes_and_enrolment(fitted, small, method):
    model = fitted[method]
    x = small.samples[:5]
    p = model.known_proba(x)
    assert p.shape == (5, 12) and np.allclose(p.sum(axis=1), 1)
    s = model.novelty_score(x)
    assert s.shape == (5,) and ((s >= 0) & (s <= 1)).all()
    assert model.novelty_tuning is not None and np.isfinite(model.novelty_threshold)
    novel = model.add_novel_classes(["n1", "n2"], [[1] + [0] * 18, [0, 1] + [0] * 17])
    assert model.registry.novel_names == []  # the original is untouched
    q = novel.novel_proba(x)
    assert q.shape == (5, 2) and np.allclose(q.sum(axis=1), 1)
    # one-shot for one class only: probabilities still sum to 1
    shot = novel.add_one_shot("n1", small.samples[:1])
    q1 = shot.novel_proba(small.samples)
    assert np.allclose(q1.sum(axis=1), 1)
    # with a sample for every class, the sample itself goes to its own class (nearest mean)
    both = shot.add_one_shot("n2", small.samples[-1:])
    assert both.novel_proba(small.samples[[0, -1]]).argmax(axis=1).tolist() == [0, 1]
    answers = both.recognize(small.samples[:3], top_k=2)
    assert len(answers) == 3 and all(len(a.top_k) == 2 for a in answers)


@pytest.mark.parametrize("method", BASELINES)
def test_bad_input_and_bundles(fitted, small, method):
    model = fitted[method]
    with pytest.raises(InputShapeError):
        model.known_proba(np.zeros((2, 5)))
    bad = small.samples[:2].copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(NonFiniteInputError):
        model.novelty_score(bad)
    with pytest.raises(FrameworkError, match="no enrolment options"):
        model.add_novel_classes(["n1"], [[1] + [0] * 18], synthesis="genf")
    with pytest.raises(NotImplementedError, match="evaluation-only"):
        model.get_state()
    with pytest.raises(NotImplementedError, match="evaluation-only"):
        bundle.to_bytes(model)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: ExtraTreesRecognizer(n_estimators=0), "n_estimators must be at least 1, got 0"),
        (lambda: DAPRecognizer(attribute_model="svm"), "attribute_model must be one of"),
        (lambda: DAPRecognizer(C=-1.0), "C must be positive or 'auto', got -1.0"),
        (lambda: DAPRecognizer(clip=0.5), r"clip must lie in \(0, 0.5\), got 0.5"),
        (lambda: ESZSLRecognizer(gamma=0.0), r"gamma must be positive or None \(chosen"),
        (lambda: ESZSLRecognizer(signature="cosine"), "signature modes must be among"),
        (lambda: ESZSLRecognizer(gammas=()), "gammas must be positive values"),
        (lambda: ESZSLRecognizer(novelty_val_fraction=1.5), "novelty_val_fraction must lie in"),
    ],
)
def test_bad_hyper_parameters(make, message, small):
    model = make()  # the constructor only stores its arguments
    with pytest.raises(FrameworkError, match=message):
        model.fit(small)  # fit checks them before any work
    assert model.input_shape is None


def test_a_given_signature_needs_no_valid_candidates(small):
    # as before: signature_modes are only the candidates when no signature is given
    model = ESZSLRecognizer(n_estimators=5, signature="l2", signature_modes=("bogus",), gamma=1.0)
    assert model.fit(small).signature_ == "l2"


def test_dap_scores_follow_lampert():
    # two attributes, prior p(a)=0.5: the class whose vector matches the predictions wins
    p = np.array([[0.9, 0.2]])
    classes = np.array([[1, 0], [0, 1], [1, 1]])
    s = dap_log_scores(p, classes, np.array([0.5, 0.5]), clip=0.01)
    expected = np.log([0.9 * 0.8, 0.1 * 0.2, 0.9 * 0.2]) - np.log(0.25)
    assert np.allclose(s[0], expected)
    # dividing by the prior: predictions equal to the prior score every class 0
    prior = np.array([0.3, 0.6])
    assert np.allclose(dap_log_scores(prior[None], classes, prior, clip=0.01), 0)


def test_joint_logistic_matches_scikit_learn():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 6))
    t = (x @ rng.normal(size=(6, 2)) + rng.normal(size=(200, 2)) > 0).astype(float)
    w, b = fit_logistic(x, t, C=0.5)
    for j in range(2):
        lr = LogisticRegression(C=0.5, tol=1e-10, max_iter=10_000).fit(x, t[:, j])
        assert np.allclose(lr.coef_[0], w[:, j], atol=1e-3)
        assert abs(lr.intercept_[0] - b[j]) < 1e-3


@pytest.mark.parametrize("n,d", [(40, 6), (12, 30)])  # primal and dual (n < d) forms
def test_eszsl_closed_form(n, d):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(n, d))
    labels = rng.integers(0, 4, n)
    sig = rng.integers(0, 2, (4, 3)).astype(float)
    y = -np.ones((n, 4))
    y[np.arange(n), labels] = 1
    direct = (
        np.linalg.inv(x.T @ x + 2.0 * np.eye(d))
        @ x.T
        @ y
        @ sig
        @ np.linalg.inv(sig.T @ sig + 0.5 * np.eye(3))
    )
    assert np.allclose(eszsl_fit(x, labels, sig, 2.0, 0.5), direct)


def test_eszsl_hyper_parameters_come_from_the_grid_on_validation_objects(small):
    model = ESZSLRecognizer(
        n_estimators=20,
        gammas=(1.0, 100.0),
        lambdas=(0.1, 10.0),
        signature_modes=("raw", "centered"),
        val_folds=2,
    )
    model.fit(small)
    assert model.gamma_ in (1.0, 100.0) and model.lambda_ in (0.1, 10.0)
    assert model.signature_ in ("raw", "centered")
    assert len(model.zsl_validation_) == 8  # every grid point was scored on validation objects
    fixed = ESZSLRecognizer(n_estimators=20, gamma=3.0, lam=0.3, signature="l2").fit(small)
    assert (fixed.signature_, fixed.gamma_, fixed.lambda_) == ("l2", 3.0, 0.3)
    assert fixed.zsl_validation_ == {}


def test_signature_normalisations():
    a = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
    mean = a.mean(axis=0)
    assert np.array_equal(signatures(a, "raw", mean), a)
    assert np.allclose(signatures(a, "centered", mean), [[0.5, -0.5, 0], [-0.5, 0.5, 0]])
    assert np.allclose(np.linalg.norm(signatures(a, "l2", mean), axis=1), 1)
    assert np.allclose(
        signatures(a, "centered_l2", mean), [[2**-0.5, -(2**-0.5), 0], [-(2**-0.5), 2**-0.5, 0]]
    )
