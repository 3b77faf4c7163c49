"""The paper's pipeline end to end on simulated data."""

import numpy as np

from app.framework.paper import PaperRecognizer


def _acc(pred, labels):
    return float((np.asarray(pred) == labels).mean())


def test_known_classes_are_recognised_on_held_out_trials(fitted, sim_split):
    test = sim_split["test"]
    acc = _acc(fitted.known_proba(test.samples).argmax(1), test.labels)
    assert acc > 0.6, acc  # chance is 1/30
    assert fitted.metrics["n_known_classes"] == 30
    assert set(fitted.metrics["timings"]) >= {"encoder_s", "novelty_s", "generator_s", "total_s"}


def test_novelty_threshold_was_tuned_on_validation_objects(fitted, sim_split):
    t = fitted.novelty_tuning
    assert fitted.novelty_threshold == t.threshold
    assert len(t.thresholds) == len(t.known_kept) == len(t.val_novel) > 10
    # novel objects are flagged more often than held-out trials of known ones
    novel_rate = fitted.is_novel(sim_split["novel"].samples).mean()
    known_rate = fitted.is_novel(sim_split["test"].samples).mean()
    assert novel_rate > known_rate


def test_zero_shot_beats_chance_by_a_clear_margin(with_novel, sim_split):
    novel = sim_split["novel"]
    acc = _acc(with_novel.novel_proba(novel.samples).argmax(1), novel.labels)
    assert acc > 2.0 / 6, acc  # chance is 1/6


def test_gen_f_and_no_gan_variants_are_available(fitted, sim_split):
    novel = sim_split["novel"]
    for options in ({"synthesis": "genf"}, {"generator": "alg1"}):
        model = fitted.add_novel_classes(novel.class_names, novel.class_attributes, **options)
        assert model.novel_proba(novel.samples).shape == (len(novel), 6)


def test_enrolment_leaves_the_original_model_untouched(fitted, with_novel):
    assert fitted.registry.novel_names == []
    assert len(with_novel.registry.novel_names) == 6
    assert with_novel.encoder_ is not fitted.encoder_
    for a, b in zip(fitted.encoder_.parameters(), with_novel.encoder_.parameters(), strict=True):
        assert (a == b).all()  # CONV_XF untouched by zero-shot enrolment


def test_one_shot_sample_improves_its_class(with_novel, sim_split):
    novel = sim_split["novel"]
    trial_no = np.arange(len(novel)) % 10
    shots, rest = trial_no == 0, trial_no > 0
    model = with_novel
    for c, name in enumerate(novel.class_names):
        model = model.add_one_shot(name, novel.samples[shots & (novel.labels == c)])
    zsl = _acc(with_novel.novel_proba(novel.samples[rest]).argmax(1), novel.labels[rest])
    osl = _acc(model.novel_proba(novel.samples[rest]).argmax(1), novel.labels[rest])
    assert osl >= zsl and osl > 0.5, (zsl, osl)
    assert all(len(model.registry.novel_samples[n]) == 1 for n in novel.class_names)


def test_recognize_routes_by_novelty(with_novel, sim_split):
    x = np.concatenate([sim_split["test"].samples[:10], sim_split["novel"].samples[:10]])
    results = with_novel.recognize(x, top_k=3)
    assert len(results) == 20
    for r in results:
        assert r.kind == ("novel" if r.is_novel else "known")
        assert len(r.top_k) == 3 and r.top_k[0].class_name == r.class_name
        probs = [s.probability for s in r.top_k]
        assert probs == sorted(probs, reverse=True) and 0 <= probs[-1] <= probs[0] <= 1
    assert {r.kind for r in results} == {"known", "novel"}


def test_without_novel_classes_a_novel_sample_is_answered_from_known_ones(fitted, sim_split):
    r = fitted.recognize(sim_split["novel"].samples[:5])
    assert all(x.kind == "known" and x.class_name in fitted.registry.known_names for x in r)


def test_training_is_deterministic_under_a_seed(sim_split):
    small = sim_split["train"].select_classes(np.arange(8))
    params = dict(seed=5, encoder_epochs=3, alg1_epochs=5, alg2_epochs=2)
    a = PaperRecognizer(**params).fit(small)
    b = PaperRecognizer(**params).fit(small)
    np.testing.assert_allclose(
        a.known_proba(small.samples[:5]), b.known_proba(small.samples[:5]), rtol=1e-5
    )


def test_feature_space_gmm_variant_round_trips(sim_split):
    from app.framework import bundle
    from app.framework.registry import make_method

    small = sim_split["train"].select_classes(np.arange(8))
    model = make_method("paper-fgmm", encoder_epochs=3, alg1_epochs=5, alg2_epochs=2).fit(small)
    assert model.novelty_space == "features"
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    assert loaded.method == "paper-fgmm" and loaded.novelty_space == "features"
    np.testing.assert_allclose(
        loaded.novelty_score(small.samples[:4]), model.novelty_score(small.samples[:4]), rtol=1e-6
    )
