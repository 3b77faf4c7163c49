"""The kind of rebuild each round plans, and the reason its model version records."""

from __future__ import annotations

from app.store.enums import VersionReason
from app.testing.service import unused_vectors
from tests.service_fixtures import add_sample, register
from worker import loop
from worker.retrain import Rebuild


def recorded_plans(monkeypatch) -> list[tuple[Rebuild, VersionReason | None]]:
    """(rebuild, reason) of each plan the worker makes from now on; no reason where the
    plan builds nothing."""
    plans, make_plan = [], loop.make_plan

    def recording(*args, **kwargs):
        plan = make_plan(*args, **kwargs)
        plans.append((plan.rebuild, plan.reason if plan.changes_model else None))
        return plan

    monkeypatch.setattr(loop, "make_plan", recording)
    return plans


def withdraw(client, path: str) -> None:
    assert client.delete(path).status_code == 202


def test_enrolments_add_to_the_model_and_a_promotion_or_a_withdrawal_refits_it(
    client, app, worker, dataset, monkeypatch
):
    """The default method's one-shot step tunes shared parts, so a withdrawal from its novel
    part fits the model again too."""
    plans = recorded_plans(monkeypatch)
    app.state.service.settings.promotion_threshold = 2
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    cup = register(client, dataset, "cup", 1)["class"]["id"]
    worker.run_once()
    first = add_sample(client, mug, dataset.samples[0] + 0.01)["sample_id"]
    worker.run_once()
    add_sample(client, mug, dataset.samples[1] + 0.01)
    worker.run_once()  # two samples: mug is known
    withdraw(client, f"/v1/classes/{mug}/samples/{first}")
    worker.run_once()  # one sample again: mug is novel again
    withdraw(client, f"/v1/classes/{cup}")
    worker.run_once()
    r = client.patch(f"/v1/classes/{mug}", json={"attribute_vector": unused_vectors(dataset, 3)[2]})
    assert r.status_code == 202
    worker.run_once()
    assert plans == [
        (Rebuild.INCREMENTAL, VersionReason.UPDATE),
        (Rebuild.INCREMENTAL, VersionReason.UPDATE),
        (Rebuild.FULL, VersionReason.PROMOTION),
        (Rebuild.FULL, VersionReason.WITHDRAWAL),
        (Rebuild.FULL, VersionReason.WITHDRAWAL),
        (Rebuild.FULL, VersionReason.UPDATE),
    ]
    reasons = [m["reason"] for m in client.get("/v1/models").json()["models"]]
    assert reasons == ["bootstrap"] + [reason for _, reason in plans]


def test_a_separable_method_rebuilds_its_novel_part_alone(best_service, best_base, monkeypatch):
    client, _, worker = best_service
    _, dataset = best_base
    plans = recorded_plans(monkeypatch)
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    cup = register(client, dataset, "cup", 1)["class"]["id"]
    worker.run_once()
    withdraw(client, f"/v1/classes/{cup}")
    worker.run_once()
    r = client.patch(f"/v1/classes/{mug}", json={"attribute_vector": unused_vectors(dataset, 3)[2]})
    assert r.status_code == 202
    worker.run_once()
    r = client.patch(f"/v1/classes/{mug}", json={"attribute_vector": unused_vectors(dataset, 3)[2]})
    assert r.status_code == 202
    worker.run_once()  # described as it is served already: nothing to build
    assert plans == [
        (Rebuild.INCREMENTAL, VersionReason.UPDATE),
        (Rebuild.NOVEL_PART, VersionReason.WITHDRAWAL),
        (Rebuild.NOVEL_PART, VersionReason.UPDATE),
        (Rebuild.NONE, None),
    ]


def test_a_plan_reads_each_vector_of_the_base_as_the_vocabulary_does_once():
    import numpy as np

    from app.store.vocabulary import Vocabulary
    from worker.retrain import _key_of

    vocab = Vocabulary(names=("hard", "soft", "rough"), retired=frozenset({"soft"}))
    for vector in ([1.0, 0.0], [0.5, np.nan], [np.nan, np.nan]):
        data = np.asarray(vector, np.float32).tobytes()
        assert _key_of(vocab, data) == vocab.key_of_vector(vector)
        assert _key_of(vocab, data) is _key_of(vocab, data)  # remembered
    other = Vocabulary(names=("hard", "soft", "rough"))
    assert _key_of(other, np.float32([1, 0, 1]).tobytes()) == other.key_of_vector([1, 0, 1])
