"""The ``prototypes`` method: its space, its search, enrolment without a refit, its novelty
operating point and answers from some procedures, on the simulator (with and without
contact modes)."""

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score

from app.data.procedures import keep_only
from app.data.simulator import simulate_dataset
from app.framework.bundle import from_bytes, to_bytes
from app.framework.errors import FrameworkError
from app.methods.embedding import SubclassEmbedding
from app.methods.prototype_search import PrototypeSearch
from app.methods.prototypes import PrototypeRecognizer
from tests.kept_share import assert_keeps, curve_resolution

KNOWN, NOVEL, TRIALS = 40, 8, 10


def _split(modes: int = 1, seed: int = 0):
    """(train, held-out known x, y, novel objects' x, y (0-based), dataset)."""
    ds = simulate_dataset(KNOWN + NOVEL, TRIALS, seed=seed, modes=modes)
    held = (ds.trials % TRIALS) >= TRIALS - 2
    known = ds.labels < KNOWN
    train = ds.subset(np.flatnonzero(known & ~held)).select_classes(np.arange(KNOWN))
    return (
        train,
        ds.samples[known & held],
        ds.labels[known & held],
        ds.samples[~known],
        ds.labels[~known] - KNOWN,
        ds,
    )


@pytest.fixture(scope="module")
def plain():
    train, x, y, xn, yn, ds = _split()
    return PrototypeRecognizer(seed=0).fit(train), x, y, xn, yn, ds


@pytest.fixture(scope="module")
def modal():
    train, x, y, xn, yn, ds = _split(modes=3)
    return PrototypeRecognizer(seed=0).fit(train), x, y, xn, yn, ds


def test_it_recognises_held_out_trials_at_least_as_well_as_shrinkage_lda(plain):
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    from app.framework.scaling import RobustInputScaler, flatten

    model, x, y, *_ = plain
    acc = (model.known_proba(x).argmax(axis=1) == y).mean()
    train = _split()[0]
    scaler = RobustInputScaler().fit(flatten(train.samples))
    lda = LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")
    lda.fit(scaler.transform(flatten(train.samples)), train.labels)
    reference = (lda.predict(scaler.transform(flatten(x))) == y).mean()
    assert acc >= reference - 0.03, (acc, reference)
    p = model.known_proba(x)
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-9)


def test_objects_with_contact_modes_get_a_prototype_each_and_are_recognised(modal):
    model, x, y, *_ = modal
    # 3 modes of 8 training trials: most objects are split into their modes
    assert model.metrics["n_prototypes"] >= 2 * KNOWN
    assert (model.known_proba(x).argmax(axis=1) == y).mean() >= 0.95


def test_one_mode_alone_splits_no_class(plain):
    model = plain[0]
    assert model.metrics["n_prototypes"] <= KNOWN + 2


def test_the_simulators_modes_leave_every_other_value_alone_and_are_checked():
    one = simulate_dataset(5, 6, seed=3)
    three = simulate_dataset(5, 6, seed=3, modes=3)
    np.testing.assert_array_equal(one.class_attributes, three.class_attributes)
    moved = np.abs(three.samples - one.samples).reshape(5, 6, -1).mean(axis=2)
    assert (moved > 0.05).all()  # every trial moved to its mode
    # each object's modes are centred on it: its mean over whole cycles of modes stays put
    mean_one = one.samples.reshape(5, 6, -1).mean(axis=1)
    mean_three = three.samples.reshape(5, 6, -1).mean(axis=1)
    np.testing.assert_allclose(mean_one, mean_three, atol=1e-4)
    with pytest.raises(ValueError, match="modes must be an integer >= 1"):
        simulate_dataset(5, 6, modes=0)


def test_approximate_search_finds_what_exact_search_finds():
    rng = np.random.default_rng(0)
    # prototypes with a few dominant leading coordinates, as the rotated space has
    scale = np.r_[np.full(16, 3.0), np.full(48, 1.0), np.full(64, 0.3)]
    points = (rng.normal(size=(3000, 128)) * scale).astype(np.float32)
    queries = points[rng.choice(3000, 300)] + rng.normal(size=(300, 128)).astype(np.float32)
    exact = PrototypeSearch(points, exact_below=10_000)
    approx = PrototypeSearch(points, exact_below=100, search_dims=32)
    assert exact.exact and not approx.exact
    ids_e, d_e = exact.nearest(queries, 10)
    ids_a, d_a = approx.nearest(queries, 10)
    recall_1 = (ids_a[:, 0] == ids_e[:, 0]).mean()
    recall_10 = np.mean([len(set(a) & set(e)) / 10 for a, e in zip(ids_a, ids_e, strict=True)])
    assert recall_1 >= 0.97 and recall_10 >= 0.85, (recall_1, recall_10)
    # distances are exact in every coordinate, whichever search found the candidate
    np.testing.assert_allclose(d_a, approx.squared(queries, ids_a), rtol=1e-6)
    assert (np.diff(d_a, axis=1) >= 0).all()


def test_points_added_after_the_fit_are_found_and_the_index_is_shared():
    import copy

    rng = np.random.default_rng(1)
    points = rng.normal(size=(50, 8)).astype(np.float32)
    search = PrototypeSearch(points)
    extra = rng.normal(size=(3, 8)).astype(np.float32) + 10.0
    grown = search.with_points(extra)
    ids, dist = grown.nearest(extra + 0.01, 1)
    assert ids[:, 0].tolist() == [50, 51, 52]
    assert len(search) == 50 and len(grown) == 53
    assert copy.deepcopy(grown).index is search.index  # a copy never copies the index


def test_a_promotion_answers_as_a_refit_does_within_the_stated_bound():
    """A class promoted from its samples (no refit) against a model fitted with it: the
    space, tau and threshold stay as fitted, so answers may differ; the docs state the
    bound this checks (held-out agreement at least 0.9, the promoted class's own trials
    recognised as well)."""
    train_all, x, y, *_ = _split()
    old = np.arange(KNOWN - 4)
    base = PrototypeRecognizer(seed=0).fit(
        train_all.subset(np.flatnonzero(np.isin(train_all.labels, old))).select_classes(old)
    )
    names = train_all.class_names
    promoted = base.with_known_samples(
        {names[c]: train_all.samples[train_all.labels == c] for c in range(KNOWN - 4, KNOWN)},
        {names[c]: train_all.class_attributes[c] for c in range(KNOWN - 4, KNOWN)},
    )
    refit = PrototypeRecognizer(seed=0).fit(train_all)
    assert promoted.registry.known_names == list(refit.registry.known_names)
    a = promoted.known_proba(x).argmax(axis=1)
    b = refit.known_proba(x).argmax(axis=1)
    assert (a == b).mean() >= 0.9
    new = y >= KNOWN - 4
    assert (a[new] == y[new]).mean() >= (b[new] == y[new]).mean() - 0.15
    assert len(promoted.search_) == len(base.search_) + 4  # one prototype each, no refit
    assert promoted.search_.index is base.search_.index


def test_one_shot_and_zero_shot_classes_are_recognised(plain):
    model, _, _, xn, yn, ds = plain
    names = [f"novel-{i}" for i in range(NOVEL)]
    vectors = ds.class_attributes[KNOWN:]
    zsl = model.add_novel_classes(names, vectors)
    p = zsl.novel_proba(xn)
    assert p.shape == (len(xn), NOVEL)
    assert (p.argmax(axis=1) == yn).mean() > 1.5 / NOVEL  # above chance
    shot = zsl
    for i in range(NOVEL):
        shot = shot.add_one_shot(names[i], xn[yn == i][:1])
    rest = np.concatenate([np.flatnonzero(yn == i)[1:] for i in range(NOVEL)])
    acc_shot = (shot.novel_proba(xn[rest]).argmax(axis=1) == yn[rest]).mean()
    assert acc_shot >= 0.7  # 0.74 to 0.90 over data seeds 0-3 (on 8 novel objects)
    assert shot.search_.index is model.search_.index


def test_the_threshold_keeps_the_stated_share_of_known_touches_it_never_saw(plain):
    """The threshold is the kept-share quantile of a probe's held-out trials: it keeps that
    share of them, to one probe touch; on held-out trials of the fitted objects (which
    neither the probe nor the model saw: 80 touches, 2 of each of 40 objects) it keeps the
    stated share within 3 binomial sigmas of 80 touches and the curve's resolution (0.95
    measured), and it detects most touches of objects never seen."""
    model, x, _, xn, *_ = plain
    assert model.known_kept == 0.9
    tuning = model.novelty_tuning
    resolution = curve_resolution(tuning.known_kept)
    assert abs(tuning.known_kept_at_threshold - 0.9) <= resolution
    kept = (model.novelty_score(x) <= model.novelty_threshold).mean()
    assert_keeps(kept, 0.9, len(x), resolution)
    detected = (model.novelty_score(xn) > model.novelty_threshold).mean()
    assert detected >= 0.4, detected
    scores = np.r_[model.novelty_score(x), model.novelty_score(xn)]
    truth = np.r_[np.zeros(len(x)), np.ones(len(xn))]
    assert roc_auc_score(truth, scores) >= 0.8


def test_the_kept_share_is_a_setting():
    """A lower share moves the threshold down and keeps fewer unseen known trials: each
    keeps its stated share of the 80 held-out touches, within 3 binomial sigmas and the
    curve's resolution (0.49 for 0.5 and 0.99 for 0.99 measured on 2026-11-28;
    docs/BENCHMARKS.md gives the figures at 0.9). The deployed model, fitted on one trial
    more of each object than the probe that set the threshold, has its shrinkage rescaled
    so that its scores sit as the probe's do."""
    train, x, *_ = _split()
    strict = PrototypeRecognizer(seed=0, known_kept=0.5).fit(train)
    loose = PrototypeRecognizer(seed=0, known_kept=0.99).fit(train)
    assert strict.novelty_threshold < loose.novelty_threshold
    kept_strict = (strict.novelty_score(x) <= strict.novelty_threshold).mean()
    kept_loose = (loose.novelty_score(x) <= loose.novelty_threshold).mean()
    assert kept_strict < kept_loose, (kept_strict, kept_loose)
    assert_keeps(kept_strict, 0.5, len(x), curve_resolution(strict.novelty_tuning.known_kept))
    assert_keeps(kept_loose, 0.99, len(x), curve_resolution(loose.novelty_tuning.known_kept))
    with pytest.raises(FrameworkError, match="known_kept"):
        PrototypeRecognizer(known_kept=1.5).fit(train)


def test_an_answer_takes_another_operating_point_without_a_refit(plain):
    """``known_kept`` on an answer reads the threshold off the model's calibration curve:
    the model's own share gives about its own threshold, each share keeps that share of
    the 80 unseen known trials (within 3 binomial sigmas and the curve's resolution), a
    higher one keeps more and detects fewer unseen objects, and a share outside (0, 1) is
    refused by name."""
    model, x, _, xn, *_ = plain
    curve = model.novelty_tuning
    own = model.threshold_keeping(model.known_kept)
    step = np.diff(curve.thresholds).max()  # the curve's resolution
    assert abs(own - model.novelty_threshold) <= step
    novel = {q: model.recognize_batch(x, known_kept=q).is_novel.mean() for q in (0.5, 0.99)}
    detected = {q: model.recognize_batch(xn, known_kept=q).is_novel.mean() for q in (0.5, 0.99)}
    assert novel[0.99] < novel[0.5] and detected[0.99] <= detected[0.5], (novel, detected)
    for share in (0.5, 0.99):
        assert_keeps(1 - novel[share], share, len(x), curve_resolution(curve.known_kept))
    default = model.recognize_batch(x[:5])
    assert (default.is_novel == (model.novelty_score(x[:5]) > model.novelty_threshold)).all()
    for bad in (0.0, 1.0, 1.5):
        with pytest.raises(FrameworkError, match="known_kept must lie in"):
            model.recognize_batch(x[:1], known_kept=bad)


def test_missing_procedures_are_answered_by_the_same_models_marginal(plain):
    model, x, y, *_ = plain
    assert model.answers_from_some_procedures
    assert model.first_procedure in model.procedures
    full = (model.known_proba(x).argmax(axis=1) == y).mean()
    for j in range(len(model.procedures)):
        part = keep_only(x, model.procedures, [j])
        batch = model.recognize_batch(part)
        assert len(batch.answers()) == len(x)
    two = keep_only(x, model.procedures, [0, 2])
    _, known_p, _ = model._subset_scores(two, np.array([0, 2]))
    assert 0.5 * full <= (known_p.argmax(axis=1) == y).mean() <= full + 0.05
    answers = model.recognize(two)
    # a procedure to do next is named while the answer is unsure
    assert any(a.next_procedure in model.procedures for a in answers)


def test_a_bundle_reads_back_with_the_same_answers(plain):
    model, x, _, xn, _, ds = plain
    enrolled = model.add_novel_classes(["n0"], ds.class_attributes[KNOWN : KNOWN + 1])
    enrolled = enrolled.add_one_shot("n0", xn[:1])
    enrolled = enrolled.with_known_samples({"grown": xn[-4:]})
    again = from_bytes(to_bytes(enrolled))
    np.testing.assert_allclose(again.known_proba(x), enrolled.known_proba(x), atol=1e-6)
    np.testing.assert_allclose(again.novelty_score(x), enrolled.novelty_score(x), atol=1e-6)
    np.testing.assert_allclose(again.novel_proba(xn), enrolled.novel_proba(xn), atol=1e-6)
    assert again.novelty_threshold == enrolled.novelty_threshold


def test_bad_parameters_are_refused_with_their_names():
    train = _split()[0]
    for params, name in (
        ({"max_modes": 0}, "max_modes"),
        ({"split_ratio": 1.5}, "split_ratio"),
        ({"distance_weight": -1.0}, "distance_weight"),
        ({"search_k": 0}, "search_k"),
    ):
        with pytest.raises(FrameworkError, match=name):
            PrototypeRecognizer(**params).fit(train)


def test_the_embedding_whitens_the_within_class_spread():
    rng = np.random.default_rng(0)
    means = rng.normal(size=(30, 20)) * 3.0
    y = np.repeat(np.arange(30), 20)
    cov = np.diag(np.geomspace(0.1, 10.0, 20))
    z = means[y] + rng.multivariate_normal(np.zeros(20), cov, len(y))
    emb = SubclassEmbedding(max_modes=1).fit(z, y, 30)
    e = emb.transform(z.astype(np.float32))
    resid = e - np.stack([e[y == c].mean(axis=0) for c in range(30)])[y]
    spread = resid.var(axis=0)
    assert spread.max() / spread.min() < 4.0  # whitened, up to shrinkage
    assert emb.subclass_class_.tolist() == list(range(30))
