"""The retraining worker: enrollments become model versions, and nothing is ever lost."""

from __future__ import annotations

import os
import threading
import time

import pytest

from app.framework.recognizer import TactileRecognizer
from app.store import leases, repo
from tests.service_fixtures import add_sample, job, refit_stopped, register
from worker import loop


def test_enrollment_makes_a_new_active_version(client, worker, dataset):
    created = register(client, dataset, "mug")
    assert worker.run_once() == 1
    done = job(client, created["job"]["id"])
    assert done["status"] == "succeeded" and done["model_version"] == 2
    assert done["started_at"] and done["finished_at"] and done["error"] is None
    cls = client.get(f"/v1/classes/{created['class']['id']}").json()
    assert cls["in_active_model"] is True and cls["kind"] == "novel"
    active = client.get("/v1/models/active").json()
    assert active["version"] == 2 and active["reason"] == "update" and active["base_version"] == 1
    assert {"name": "mug", "kind": "novel"} in active["classes"]


def test_the_worker_holds_the_active_model_before_its_first_job(client, worker):
    worker.warm_up()
    with client.app.state.service.sessions() as s:
        active = repo.active_version(s)
    version, model = worker._cache
    assert version == active.version and isinstance(model, TactileRecognizer)
    assert model.input_shape == tuple(active.input_shape)


def test_one_shot_sample_is_folded_in(client, app, worker, dataset):
    created = register(client, dataset, "mug")
    worker.run_once()
    added = add_sample(client, created["class"]["id"], dataset.samples[0])
    assert worker.run_once() == 1
    assert job(client, added["job"]["id"])["model_version"] == 3
    model = app.state.service.holder.current.recognizer
    assert len(model.registry.novel_samples["mug"]) == 1
    with app.state.service.sessions() as s:
        v3 = repo.get_version(s, 3)
        assert v3.sample_ids == [added["sample_id"]]


def test_nothing_queued_means_no_work(worker, client):
    assert worker.run_once() == 0


def test_queued_enrollments_are_coalesced_into_one_version(client, worker, dataset):
    a = register(client, dataset, "a", 0)
    b = register(client, dataset, "b", 1)
    s = add_sample(client, a["class"]["id"], dataset.samples[1])
    assert worker.run_once() == 3
    versions = {job(client, x["job"]["id"])["model_version"] for x in (a, b, s)}
    assert versions == {2}
    assert [m["version"] for m in client.get("/v1/models").json()["models"]] == [1, 2]


def test_enrollments_during_a_retrain_go_into_the_next_one(client, worker, dataset, monkeypatch):
    first = register(client, dataset, "first", 0)
    late = []
    original = loop.build

    def build_and_enroll_meanwhile(*args, **kwargs):
        if not late:  # two enrollments arrive while the first retrain runs
            late.append(register(client, dataset, "second", 1))
            late.append(register(client, dataset, "third", 2))
        return original(*args, **kwargs)

    monkeypatch.setattr(loop, "build", build_and_enroll_meanwhile)
    assert worker.run_once() == 1
    assert job(client, first["job"]["id"])["model_version"] == 2
    assert [job(client, x["job"]["id"])["status"] for x in late] == ["queued", "queued"]
    assert worker.run_once() == 2
    assert {job(client, x["job"]["id"])["model_version"] for x in late} == {3}
    names = {c["name"] for c in client.get("/v1/models/active").json()["classes"]}
    assert {"first", "second", "third"} <= names


def test_failed_job_keeps_the_previous_model_and_records_its_error(
    client, worker, dataset, monkeypatch
):
    created = register(client, dataset, "doomed")

    def broken(self, *args, **kwargs):
        raise RuntimeError("generator diverged")

    monkeypatch.setattr(TactileRecognizer, "add_novel_classes", broken)
    assert worker.run_once() == 1
    failed = job(client, created["job"]["id"])
    assert failed["status"] == "failed" and "generator diverged" in failed["error"]
    assert failed["model_version"] is None
    assert client.get("/v1/models/active").json()["version"] == 1
    assert len(client.get("/v1/models").json()["models"]) == 1
    assert client.get(f"/v1/classes/{created['class']['id']}").json()["in_active_model"] is False

    # the failure is final for that enrollment, but later ones go through
    monkeypatch.undo()
    later = register(client, dataset, "fine", 1)
    assert worker.run_once() == 1
    assert job(client, later["job"]["id"])["status"] == "succeeded"
    classes = {c["name"] for c in client.get("/v1/models/active").json()["classes"]}
    assert "fine" in classes and "doomed" not in classes


def test_a_failed_registration_can_be_retried(client, worker, dataset, monkeypatch):
    created = register(client, dataset, "flaky")
    monkeypatch.setattr(
        TactileRecognizer,
        "add_novel_classes",
        lambda *a, **k: (_ for _ in ()).throw(RuntimeError("out of memory")),
    )
    worker.run_once()
    monkeypatch.undo()
    assert job(client, created["job"]["id"])["status"] == "failed"
    again = register(client, dataset, "flaky")  # same name and attributes: a new attempt
    assert (
        again["class"]["id"] == created["class"]["id"]
        and again["job"]["id"] != created["job"]["id"]
    )
    assert worker.run_once() == 1
    assert job(client, again["job"]["id"])["status"] == "succeeded"
    assert client.get(f"/v1/classes/{created['class']['id']}").json()["in_active_model"] is True
    r = client.post(
        "/v1/classes", json={"name": "flaky", "attributes": again["class"]["attributes"]}
    )
    assert r.status_code == 409  # now it exists for real


def test_one_bad_enrollment_does_not_sink_the_batch(client, worker, dataset, monkeypatch):
    good = register(client, dataset, "good", 0)
    bad = register(client, dataset, "bad", 1)
    original = TactileRecognizer.add_novel_classes

    def picky(self, names, vectors, **kw):
        if "bad" in names:
            raise ValueError("cannot synthesise features for 'bad'")
        return original(self, names, vectors, **kw)

    monkeypatch.setattr(TactileRecognizer, "add_novel_classes", picky)
    assert worker.run_once() == 2
    assert job(client, good["job"]["id"])["status"] == "succeeded"
    bad_job = job(client, bad["job"]["id"])
    assert bad_job["status"] == "failed" and "'bad'" in bad_job["error"]


def test_sample_of_a_failed_class_fails_with_a_reason(client, worker, dataset, monkeypatch):
    created = register(client, dataset, "doomed")
    sample = add_sample(client, created["class"]["id"], dataset.samples[0])
    monkeypatch.setattr(
        TactileRecognizer,
        "add_novel_classes",
        lambda *a, **k: (_ for _ in ()).throw(RuntimeError("boom")),
    )
    worker.run_once()
    monkeypatch.undo()
    assert job(client, created["job"]["id"])["status"] == "failed"
    failed = job(client, sample["job"]["id"])
    assert failed["status"] == "failed" and "registration failed" in failed["error"]


def test_job_left_running_by_a_crashed_worker_is_requeued_and_done(client, app, worker, dataset):
    created = register(client, dataset, "orphan")
    with app.state.service.sessions() as s:  # a worker claimed it, then died
        repo.claim_queued_jobs(s, "crashed-host:1:dead")
    assert job(client, created["job"]["id"])["status"] == "running"
    assert worker.run_once() == 1  # a (re)started worker takes it up again
    done = job(client, created["job"]["id"])
    assert done["status"] == "succeeded" and done["model_version"] == 2
    with app.state.service.sessions() as s:
        assert repo.jobs_by_status(s) == {"succeeded": 1}


def test_a_worker_whose_lease_is_live_elsewhere_waits(client, app, worker, dataset):
    register(client, dataset, "wait")
    with app.state.service.sessions() as s:
        assert leases.try_acquire(s, loop.LEASE, "other-host:1:live", ttl=60)
    assert worker.run_once() == 0  # another worker is retraining
    with app.state.service.sessions() as s:
        leases.release(s, loop.LEASE, "other-host:1:live")
    assert worker.run_once() == 1


def test_promotion_to_known_after_threshold_real_samples(client, app, worker, dataset):
    app.state.service.settings.promotion_threshold = 2
    created = register(client, dataset, "promoted")
    cid = created["class"]["id"]
    worker.run_once()
    add_sample(client, cid, dataset.samples[0] + 0.01)
    worker.run_once()
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "novel"
    last = add_sample(client, cid, dataset.samples[1] + 0.01)
    assert worker.run_once() == 1  # reaches the threshold: full retrain (``paper``)
    assert job(client, last["job"]["id"])["status"] == "succeeded"
    cls = client.get(f"/v1/classes/{cid}").json()
    assert cls["kind"] == "known" and cls["in_active_model"] is True and cls["n_samples"] == 2
    active = client.get("/v1/models/active").json()
    assert active["reason"] == "promotion"
    assert {"name": "promoted", "kind": "known"} in active["classes"]
    assert sum(c["kind"] == "known" for c in active["classes"]) == dataset.n_classes + 1
    assert app.state.service.holder.current.recognizer.registry.known_names[-1] == "promoted"


def test_promotions_grow_the_known_part_until_the_share_then_refit(best_service, best_base):
    """With ``best``, promotions are learnt without a refit while the samples so learnt stay within
    ``grow_fraction`` of the fitted ones (the model counts them); the one beyond refits
    everything (a fresh fit has learnt nothing so)."""
    client, app, worker = best_service
    dataset = best_base[1]
    settings = app.state.service.settings
    settings.promotion_threshold = 2
    fitted = app.state.service.holder.current.recognizer.metrics["n_train_samples"]
    settings.grow_fraction = 3.5 / fitted  # room for one promotion of 2 samples, not two
    for name, rows in (("first", (0, 1)), ("second", (2, 3))):
        cid = register(client, dataset, name, rows[0])["class"]["id"]
        worker.run_once()
        for r in rows:
            add_sample(client, cid, dataset.samples[r] + 0.01)
        worker.run_once()
        assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
        assert client.get("/v1/models/active").json()["reason"] == "promotion"
        served = app.state.service.holder.current.recognizer
        if name == "first":
            assert served.metrics["n_grown_samples"] == 2
    assert "n_grown_samples" not in served.metrics  # beyond the share: fitted again
    assert served.registry.known_names[-2:] == ["first", "second"]


def test_rollback_then_retrain_brings_enrollments_back(client, worker, dataset):
    a = register(client, dataset, "a", 0)
    worker.run_once()
    client.post("/v1/models/1/activate")
    b = register(client, dataset, "b", 1)
    worker.run_once()
    active = client.get("/v1/models/active").json()
    assert active["base_version"] == 1
    assert {"a", "b"} <= {c["name"] for c in active["classes"]}
    assert client.get(f"/v1/classes/{a['class']['id']}").json()["in_active_model"] is True
    assert job(client, b["job"]["id"])["model_version"] == active["version"]


def test_embedded_worker_thread_processes_jobs(tmp_path, base_model):
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.testing.service import quick_settings
    from tests.service_fixtures import wait_for_job

    settings = quick_settings(tmp_path / "e", embedded_worker=True)
    with TestClient(create_app(settings, trainer=lambda: base_model)) as c:
        created = register(c, base_model[1], "embedded")
        done = wait_for_job(c, created["job"]["id"])
        assert done["status"] == "succeeded"
        assert c.get(f"/v1/classes/{created['class']['id']}").json()["in_active_model"] is True


def test_run_worker_holds_the_store_until_it_stops_on_request(settings, store):
    from app.store.in_use import StoreInUseError, closed_to_service, lock_path
    from worker import run_worker

    def restorable() -> bool:
        try:
            with closed_to_service(settings.sqlalchemy_url):
                return True
        except StoreInUseError:
            return False

    guarded = lock_path(settings.sqlalchemy_url) is not None  # SQLite files only
    stop = threading.Event()
    thread = threading.Thread(target=run_worker, args=(settings, stop))
    thread.start()
    deadline = time.monotonic() + 30
    while guarded and restorable() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not (guarded and restorable())  # a running worker's store is not restored under it
    time.sleep(0.3)
    stop.set()
    thread.join(10)
    assert not thread.is_alive()
    assert restorable()


@pytest.mark.skipif(not hasattr(os, "nice"), reason="niceness is POSIX")
def test_retrains_run_at_the_worker_niceness_and_the_api_keeps_its_own(worker):
    """Linux niceness is per thread: the worker's thread yields the CPU, the rest do not."""
    base = os.getpriority(os.PRIO_PROCESS, 0)
    seen = []

    def run() -> None:
        stop = threading.Event()
        stop.set()
        worker.run(stop)
        seen.append(os.getpriority(os.PRIO_PROCESS, 0))

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(10)
    assert worker.settings.worker_nice > 0
    assert seen == [min(19, base + worker.settings.worker_nice)]
    assert os.getpriority(os.PRIO_PROCESS, 0) == base


def test_job_timings_reach_the_metrics_of_every_api_process(client, worker, dataset):
    register(client, dataset, "timed")
    worker.run_once()
    text = client.get("/metrics").text
    assert 'tactile_enrollment_to_live_seconds_count{status="succeeded"} 1.0' in text
    assert 'tactile_job_duration_seconds_count{status="succeeded"} 1.0' in text
    assert 'tactile_enrollments_total{kind="class"} 1.0' in text
    text = client.get("/metrics").text  # a second scrape does not count the job again
    assert 'tactile_enrollment_to_live_seconds_count{status="succeeded"} 1.0' in text


def test_old_versions_are_pruned_and_the_kept_ones_still_roll_back(client, app, dataset, sample):
    """keep_versions=2: after four enrollments the store holds the bootstrap version and
    the two newest; a pruned version cannot be activated, a kept one can."""
    from app.store.integrity import check_store
    from worker import Worker

    settings = app.state.service.settings.model_copy(update={"keep_versions": 2})
    worker = Worker(
        settings, app.state.service.sessions, on_activate=app.state.service.holder.serve
    )
    for i, name in enumerate(["a", "b", "c", "d"]):
        register(client, dataset, name, i)
        assert worker.run_once() == 1
    versions = [m["version"] for m in client.get("/v1/models").json()["models"]]
    assert versions == [1, 4, 5]
    assert "tactile_model_versions_stored 3.0" in client.get("/metrics").text
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 5
    r = client.post("/v1/models/3/activate")
    assert r.status_code == 404 and r.json()["errors"][0]["field"] == "version"
    assert client.post("/v1/models/4/activate").status_code == 200
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 4
    assert check_store(settings.sqlalchemy_url) == []


def test_a_promotion_whose_refit_runs_out_of_memory_fails_clearly_and_the_model_stays(
    client, app, worker, dataset
):
    """The refit runs in a child process (worker/refit.py); stopped for memory, its jobs
    fail with that reason, the class stays novel, the active model answers throughout the
    round, and the next sample with room for the refit promotes it. (The limit here is
    below what the child's imports take, ~250 MB: test_worker_refit stops a fit that
    grows past a limit of 1,000 MiB.)"""
    settings = app.state.service.settings
    cid, active, last, answers = refit_stopped(
        client, app, worker, dataset, refit_memory_limit_mb=100
    )
    assert len(answers) >= 3
    assert set(answers) == {(200, active)}
    failed = job(client, last["job"]["id"])
    assert failed["status"] == "failed"
    assert "RefitMemoryError" in failed["error"] and "memory limit of 100 MiB" in failed["error"]
    assert client.get("/v1/models/active").json()["version"] == active
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "novel"
    settings.refit_memory_limit_mb = 0  # half of the machine's memory
    add_sample(client, cid, dataset.samples[3] + 0.01)
    assert worker.run_once() == 1
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
