"""A broken sensor is not answered as an object, and every answer names its operating
point. An answer whose input is an outlier (zeros, a saturated sensor, one dead channel)
abstains by default in ``recognize``, ``RecognitionBatch.answers`` and ``records`` (no
class, ``kind`` ``input_outlier``), for single samples and fused groups alike, and gives
the model's guess with ``outliers="answer"``; sound samples are answered as before either
way. Each answer records the threshold it was routed by and the share of known touches
asked for (``operating_point`` ``known_kept``), or none (``model_default``)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.recognizer import INPUT_OUTLIER
from app.framework.registry import make_method


@pytest.fixture(scope="module")
def model_and_data():
    data = simulate_dataset(n_objects=12, trials_per_object=6, seed=5)
    model = make_method("prototypes").fit(data)
    return model, data


def broken_inputs(x: np.ndarray) -> np.ndarray:
    """Zeros, a saturated sensor and one dead channel, made from sound sample ``x``."""
    dead = x.copy()
    dead[4] = 0.0
    saturated = np.full_like(x, float(np.abs(x).max()) * 1e3)
    return np.stack([np.zeros_like(x), saturated, dead])


def test_broken_inputs_abstain_and_sound_ones_are_answered(model_and_data):
    model, data = model_and_data
    sound = data.samples[:2]
    x = np.concatenate([sound, broken_inputs(sound[0])])
    batch = model.recognize_batch(x)
    assert batch.input_outlier.tolist() == [False, False, True, True, True]

    answers = model.recognize(x)
    assert [a.kind for a in answers[2:]] == [INPUT_OUTLIER] * 3
    for a in answers[2:]:
        assert a.class_name is None and a.is_novel is None and a.top_k == ()
        assert a.input_outlier is True and a.novelty_score == a.novelty_score  # not NaN
    guessed = model.recognize(x, outliers="answer")
    assert answers[:2] == guessed[:2]  # sound samples: the same answer either way
    for a in guessed[2:]:
        assert a.kind in ("known", "novel") and a.class_name in model.registry.all_names
        assert a.input_outlier is True and a.top_k

    records = batch.records({n: i for i, n in enumerate(model.registry.all_names)})
    for r in records[2:]:
        assert (r["kind"], r["class_name"], r["class_id"], r["is_novel"], r["top_k"]) == (
            INPUT_OUTLIER,
            None,
            None,
            None,
            [],
        )
    assert (
        records[:2]
        == batch.records({n: i for i, n in enumerate(model.registry.all_names)}, outliers="answer")[
            :2
        ]
    )
    assert [r["class_name"] for r in batch.records(outliers="answer")[2:]] == [
        g.class_name for g in guessed[2:]
    ]


def test_a_group_with_one_broken_touch_abstains(model_and_data):
    model, data = model_and_data
    x = np.concatenate([data.samples[:2], broken_inputs(data.samples[0])[2:]])
    answers = model.recognize(x, groups=np.array([0, 0, 1]))
    assert answers[0].kind != INPUT_OUTLIER and answers[0].class_name is not None
    assert answers[1].kind == INPUT_OUTLIER and answers[1].class_name is None


def test_an_unknown_policy_is_refused_by_name(model_and_data):
    model, data = model_and_data
    with pytest.raises(ValueError, match="outliers must be one of 'abstain', 'answer'"):
        model.recognize(data.samples[:1], outliers="guess")
    with pytest.raises(ValueError, match="'guess'"):
        model.recognize_batch(data.samples[:1]).records(outliers="guess")


def test_each_answer_names_the_threshold_and_operating_point_it_used(model_and_data):
    model, data = model_and_data
    x = data.samples[:6]
    own = model.recognize_batch(x)
    assert own.novelty_threshold.tolist() == [model.novelty_threshold] * 6
    assert {(a.known_kept, a.operating_point) for a in own.answers()} == {(None, "model_default")}
    kept = model.operating_point()  # the served default, the model holding a curve
    assert kept == 0.90
    at = model.recognize_batch(x, known_kept=kept)
    threshold = model.threshold_keeping(kept)
    records = at.records()
    assert {(r["novelty_threshold"], r["known_kept"], r["operating_point"]) for r in records} == {
        (threshold, 0.90, "known_kept")
    }
    assert at.is_novel.tolist() == (at.novelty_score > threshold).tolist()
    assert at[2:4].novelty_threshold.tolist() == [threshold] * 2 and at[2:4].known_kept == 0.90
    assert model.operating_point(0.97) == 0.97
    bare = copy.copy(model)
    bare.novelty_tuning = None
    assert bare.operating_point() is None and bare.operating_point(None, 0.8) is None
