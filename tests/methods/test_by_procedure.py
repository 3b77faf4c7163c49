"""``best`` answers samples that lack procedures, from the ones they hold, and says which
procedure to do next; complete samples are answered exactly as before."""

from __future__ import annotations

import numpy as np
import pytest

from app.data import procedures
from app.data.procedures import keep_only
from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.errors import MissingProcedureError, NonFiniteInputError
from app.methods.best import BestRecognizer

PARAMS = {"seed": 0, "n_estimators": 30, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def data():
    full = simulate_dataset(n_objects=14, trials_per_object=6, seed=3)
    train = full.subset(full.trials % 6 != 0)
    test = full.subset(full.trials % 6 == 0)
    known = np.arange(12)
    return (
        train.subset(np.isin(train.labels, known)).select_classes(known),
        test.subset(np.isin(test.labels, known)).select_classes(known),
        full,
    )


@pytest.fixture(scope="module")
def model(data):
    return BestRecognizer(**PARAMS).fit(data[0])


def test_complete_samples_are_answered_as_by_the_whole_model_alone(data, model):
    train, test, _ = data
    alone = BestRecognizer(**PARAMS, by_procedure=False).fit(train)
    assert model.answers_from_some_procedures and not alone.answers_from_some_procedures
    np.testing.assert_array_equal(model.known_proba(test.samples), alone.known_proba(test.samples))
    np.testing.assert_array_equal(
        model.novelty_score(test.samples), alone.novelty_score(test.samples)
    )
    batch = model.recognize_batch(test.samples)
    assert batch.procedures == test.procedures
    assert batch.procedures_used.all() and (batch.next_procedure == -1).all()


def test_each_procedure_model_has_procedure_estimators_trees(data, model):
    # the default: as many as the whole model's (30 here), and never more
    assert {m.known_.cues_model.forest.n_trees for m in model.procedures_.models} == {30}
    more = BestRecognizer(**{**PARAMS, "n_estimators": 10}, procedure_estimators=50)
    assert {m.n_estimators for m in more.fit(data[0]).procedures_.models} == {10}
    assert all(m.procedures_ is None for m in model.procedures_.models)
    fewer = BestRecognizer(**PARAMS, procedure_estimators=7).fit(data[0])
    assert {m.known_.cues_model.forest.n_trees for m in fewer.procedures_.models} == {7}
    assert fewer.known_.cues_model.forest.n_trees == 30


def test_every_subset_of_procedures_is_answered_from_its_procedures(data, model):
    _, test, _ = data
    chance = 1 / test.n_classes
    for keep in ([0], [1], [2], [3], [0, 3], [1, 2, 3]):
        x = keep_only(test.samples, test.procedures, keep)
        p = model.known_proba(x)
        np.testing.assert_allclose(p.sum(axis=1), 1.0, rtol=1e-6)
        assert (p.argmax(axis=1) == test.labels).mean() > 3 * chance, keep
        answers = model.recognize(x, top_k=2)
        assert all(a.procedures_used == tuple(test.procedures[j] for j in keep) for a in answers)
        assert np.isfinite(model.novelty_score(x)).all()
        assert model.attribute_proba(x).shape == (len(x), model.registry.attribute_names.__len__())


def test_a_batch_may_mix_samples_of_different_procedures(data, model):
    _, test, _ = data
    x = test.samples[:3].copy()
    x[0] = keep_only(x[:1], test.procedures, [0])[0]
    x[2] = keep_only(x[2:3], test.procedures, [1, 2])[0]
    mixed = model.known_proba(x)
    for i in range(3):
        np.testing.assert_allclose(mixed[i], model.known_proba(x[i : i + 1])[0])
    used = model.recognize_batch(x).procedures_used
    assert used.tolist() == [
        [True, False, False, False],
        [True, True, True, True],
        [False, True, True, False],
    ]


def test_next_procedure_is_one_not_done_until_two_are_done_and_the_answer_confident(data, model):
    _, test, _ = data
    x = keep_only(test.samples, test.procedures, [0])
    unsure = model.recognize_batch(x, target_confidence=1.0)
    assert (unsure.next_procedure >= 1).all()  # never the one already done
    # one procedure alone is never enough, however sure its answer (MIN_PROCEDURES)
    one = model.recognize_batch(x, target_confidence=1e-9)
    assert (one.next_procedure >= 1).all()
    two = keep_only(test.samples, test.procedures, [0, 3])
    assert (model.recognize_batch(two, target_confidence=1e-9).next_procedure == -1).all()
    still = model.recognize_batch(two, target_confidence=1.0).next_procedure
    assert np.isin(still, [1, 2]).all()
    assert model.first_procedure in test.procedures


def test_the_next_procedure_has_the_largest_expected_gain_per_second(data, model, monkeypatch):
    """A procedure that costs far less robot time wins where gains are alike; made
    ten times dearer, the same procedure is chosen less often."""
    _, test, _ = data
    x = keep_only(test.samples, test.procedures, [0])
    known_p = model.known_proba(x)
    used = np.zeros((len(x), 4), bool)
    used[:, 0] = True
    ask = np.ones(len(x), bool)
    parts = model.procedures_
    chosen = parts.next_procedures(known_p, used, ask)
    cheap = min(test.procedures[1:], key=procedures.SECONDS.__getitem__)
    share = (chosen == test.procedures.index(cheap)).mean()
    monkeypatch.setitem(procedures.SECONDS, cheap, procedures.SECONDS[cheap] * 10)
    dearer = parts.next_procedures(known_p, used, ask)
    assert share > 0 and (dearer == test.procedures.index(cheap)).mean() < share


def test_a_confident_answer_held_for_a_second_procedure_gets_a_quick_one_not_the_slowest(
    data, model
):
    """Where every procedure left is expected to lower a confident answer's probability
    (it is held only by MIN_PROCEDURES), dividing that loss by seconds made the slowest
    procedure the least negative; it must be the one no other beats in both loss and time."""
    _, test, _ = data
    x = keep_only(test.samples, test.procedures, [0])
    unsure = model.known_proba(x)
    k = unsure.shape[1]
    sure = np.full_like(unsure, 0.01 / (k - 1))  # answers as sure as the target allows
    sure[np.arange(len(x)), test.labels] = 0.99
    known_p = np.concatenate([unsure, sure])
    used = np.zeros((len(known_p), 4), bool)
    used[:, 0] = True
    parts = model.procedures_
    gains = parts.expected_gains(known_p, used)
    losing = (gains[:, 1:] < 0).all(axis=1)
    winning = (gains[:, 1:] > 0).any(axis=1)
    assert losing.sum() >= 3 and winning.sum() >= 1
    seconds = np.array([2.0, 3.0, 4.0, 5.0])
    for slowest in (1, 2, 3):
        s = seconds.copy()
        s[slowest] = 100.0
        chosen = parts.next_procedures(known_p, used, np.ones(len(known_p), bool), s)
        assert (chosen[losing] != slowest).all()
        for i in np.flatnonzero(losing):
            c = chosen[i]
            others = [j for j in (1, 2, 3) if j != c]
            # nobody both loses less and takes no longer
            assert not any(gains[i, j] >= gains[i, c] and s[j] <= s[c] for j in others)
        # where a procedure gains, the largest gain per second, as before
        best = (gains[winning] / s).argmax(axis=1)
        np.testing.assert_array_equal(chosen[winning], best)


def test_a_sample_missing_part_of_a_procedure_or_all_of_them_is_refused(data, model):
    _, test, _ = data
    x = test.samples[:1].copy()
    x[0, 0, :5] = np.nan  # five values of the first procedure's first row
    with pytest.raises(MissingProcedureError, match="procedure 'squeeze' is partly missing"):
        model.recognize(x)
    with pytest.raises(MissingProcedureError, match="every procedure is missing"):
        model.recognize(np.full_like(x, np.nan))
    y = test.samples[:1].copy()
    y[0, 9, 3] = np.inf
    with pytest.raises(NonFiniteInputError, match="infinity"):
        model.recognize(y)


def test_models_without_per_procedure_parts_say_they_need_every_procedure(data):
    alone = BestRecognizer(**PARAMS, by_procedure=False).fit(data[0])
    x = keep_only(data[1].samples[:1], data[1].procedures, [0])
    with pytest.raises(MissingProcedureError, match="answers from every procedure"):
        alone.recognize(x)
    assert alone.first_procedure is None


def test_enrolment_keeps_the_per_procedure_models_in_step(data, model):
    train, test, full = data
    novel = full.subset(full.labels >= 12)
    names = [full.class_names[12], full.class_names[13]]
    zsl = model.add_novel_classes(names, full.class_attributes[12:14], allow_known_vectors=True)
    x = keep_only(novel.samples, novel.procedures, [0, 2])
    assert zsl.novel_proba(x).shape == (len(x), 2)
    shot = zsl.add_one_shot(names[0], novel.samples[novel.labels == 12][:1])
    for j, sub in enumerate(shot.procedures_.models):
        assert sub.shot_has_.tolist() == [True, False]  # each learnt the sample's block
        assert sub.registry.novel_samples[names[0]].shape == (1, 8, 30), j
    assert not zsl.procedures_.models[0].shot_has_.any()  # the original is untouched
    with pytest.raises(MissingProcedureError, match="need every procedure"):
        zsl.add_one_shot(names[0], x[:1])
    grown = shot.with_known_samples({names[1]: novel.samples[novel.labels == 13][:3]})
    assert grown.known_proba(x).shape == (len(x), 13)
    assert grown.procedures_.class_means.shape[0] == 13
    dropped = shot.without_novel_classes()
    assert dropped.procedures_.models[0].registry.novel_names == []


def test_a_bundle_keeps_the_per_procedure_models(data, model):
    _, test, full = data
    m = model.add_novel_classes([full.class_names[12]], full.class_attributes[12:13])
    m = m.add_one_shot(full.class_names[12], full.samples[full.labels == 12][:1])
    back = bundle.from_bytes(bundle.to_bytes(m))
    x = keep_only(test.samples, test.procedures, [1, 3])
    assert back.procedures == m.procedures and back.first_procedure == m.first_procedure
    np.testing.assert_array_equal(back.known_proba(x), m.known_proba(x))
    np.testing.assert_array_equal(back.novel_proba(x), m.novel_proba(x))
    np.testing.assert_array_equal(
        back.recognize_batch(x).next_procedure, m.recognize_batch(x).next_procedure
    )


def test_parallel_jobs_fit_the_same_models(data, model):
    # n_jobs fits the attribute classifiers side by side in threads (and the forests'
    # trees): the models must be the ones a single job fits, bit for bit
    train, test, _ = data
    assert model.n_jobs == 1
    parallel = BestRecognizer(**PARAMS, n_jobs=2).fit(train)
    for keep in ([0], [2, 3], [0, 1, 2, 3]):
        x = keep_only(test.samples, test.procedures, keep)
        np.testing.assert_array_equal(parallel.known_proba(x), model.known_proba(x))
        np.testing.assert_array_equal(parallel.novelty_score(x), model.novelty_score(x))
        np.testing.assert_array_equal(parallel.attribute_proba(x), model.attribute_proba(x))
    assert parallel.procedures_.first == model.procedures_.first
    assert [m.n_jobs for m in parallel.procedures_.models] == [2, 2, 2, 2]
