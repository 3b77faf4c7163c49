"""GET /v1/jobs/{id}: a job's progress, and waiting for it to finish (long polling)."""

from __future__ import annotations

import threading
import time

from app.testing.service import unused_vectors

PROBLEM = "application/problem+json"


def register(client, dataset) -> int:
    r = client.post(
        "/v1/classes", json={"name": "cup", "attribute_vector": unused_vectors(dataset, 1)[0]}
    )
    assert r.status_code == 202
    return r.json()["job"]["id"]


def test_a_waiting_request_answers_when_the_job_succeeds(client, app, worker, dataset):
    job_id = register(client, dataset)
    # the retrain starts once the request below is waiting: without the wait it would read "queued"
    retrain = threading.Thread(target=lambda: (time.sleep(0.5), worker.run_once()))
    retrain.start()
    try:
        job = client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()
    finally:
        retrain.join()
    assert job["status"] == "succeeded" and job["model_version"] == 2
    # this process's worker handed the version over: it serves it already
    assert app.state.service.holder.current.version == 2


def test_a_finished_jobs_answer_does_not_wait_for_this_process_to_load_its_version(
    settings, base_model, dataset
):
    """Another process's worker made version 2; this process cannot load it yet (its own
    worker is handing a version over, which a load waits for). The job is answered all the
    same, and the answer starts the load, which serves version 2 once it can (its poll
    would take an hour)."""
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from worker import Worker

    slow = settings.model_copy(update={"model_poll_seconds": 3600})
    app = create_app(slow, trainer=lambda: base_model)
    with TestClient(app) as client:
        holder = app.state.service.holder
        job_id = register(client, dataset)
        assert Worker(slow, app.state.service.sessions).run_once() == 1  # another process's
        with holder.handing_over():
            for wait in (0, 20):
                job = client.get(f"/v1/jobs/{job_id}", params={"wait": wait})
                assert job.status_code == 200, job.text
                assert job.json()["status"] == "succeeded" and job.json()["model_version"] == 2
            assert holder.current.version == 1  # answered before the version was loaded
            loads = [t for t in threading.enumerate() if t.name == "model-load"]
            assert len(loads) == 1  # the answers started one load
        loads[0].join(timeout=60)  # the handover over, the load goes on
        assert holder.current.version == 2
        x = {"samples": dataset.samples[:1].tolist()}
        r = client.post("/v1/recognize?min_model_version=2", json=x)
        assert r.status_code == 200 and r.json()["model_version"] == 2


def test_without_a_worker_the_wait_ends_with_the_status_then(client, app, dataset):
    app.state.service.holder.stop()  # its poll checks a connection out too
    job_id = register(client, dataset)
    job = client.get(f"/v1/jobs/{job_id}", params={"wait": 0.5}).json()
    assert job["status"] == "queued" and job["finished_at"] is None
    assert app.state.service.sessions.kw["bind"].pool.checkedout() == 0  # none kept while waiting
    assert client.get(f"/v1/jobs/{job_id}").json() == job  # no wait: the status at once


def test_a_finished_job_is_answered_at_once_and_an_unknown_one_is_404(client, worker, dataset):
    job_id = register(client, dataset)
    worker.run_once()
    assert client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()["status"] == "succeeded"
    r = client.get("/v1/jobs/424242", params={"wait": 5})
    assert r.status_code == 404 and r.json()["errors"][0]["field"] == "job_id"


def test_bad_waits_are_named_422(client, dataset):
    job_id = register(client, dataset)
    for wait in (-1, 21, "soon"):
        r = client.get(f"/v1/jobs/{job_id}", params={"wait": wait})
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, wait
        assert r.json()["errors"][0]["field"] == "wait"


def test_many_waiting_robots_are_woken_together_and_leave_nothing_behind(
    client, app, worker, dataset
):
    job_id = register(client, dataset)
    answers: list[dict] = []
    robots = [
        threading.Thread(
            target=lambda: answers.append(
                client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()
            )
        )
        for _ in range(4)
    ]
    for robot in robots:
        robot.start()
    deadline = time.monotonic() + 15
    while app.state.service.job_watch.waiting < 4 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert app.state.service.job_watch.waiting == 4  # one event each, no connection, no thread
    worker.run_once()
    for robot in robots:
        robot.join()
    assert [a["status"] for a in answers] == ["succeeded"] * 4
    assert app.state.service.job_watch.waiting == 0


def test_a_store_outage_while_robots_wait_is_logged_once_and_they_are_answered_after(
    client, app, worker, dataset, monkeypatch, caplog
):
    from sqlalchemy.exc import OperationalError

    from app.store import repo

    job_id = register(client, dataset)
    real, outage, failed = repo.finished_job_ids, threading.Event(), []

    def unreachable(session, ids):
        if outage.is_set():
            failed.append(ids)
            raise OperationalError("SELECT", {}, Exception("connection refused"))
        return real(session, ids)

    def retrain_during_the_outage():
        time.sleep(0.5)
        worker.run_once()
        time.sleep(0.6)  # the job has finished, but the watch cannot see it yet
        outage.clear()

    outage.set()
    monkeypatch.setattr(repo, "finished_job_ids", unreachable)
    retrain = threading.Thread(target=retrain_during_the_outage)
    retrain.start()
    try:
        with caplog.at_level("INFO", logger="app.service.job_watch"):
            job = client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()
    finally:
        retrain.join()
    assert job["status"] == "succeeded" and len(failed) >= 4
    records = [r for r in caplog.records if r.name == "app.service.job_watch"]
    assert [r.levelname for r in records] == ["ERROR", "INFO"]  # one error for the whole outage
    assert "again" in records[1].getMessage()


def test_a_shutdown_answers_waiting_robots_at_once_with_the_status_then(client, app, dataset):
    app.state.service.holder.stop()
    job_id = register(client, dataset)
    answers: list[tuple[float, dict]] = []

    def robot():
        started = time.monotonic()
        job = client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()
        answers.append((time.monotonic() - started, job))

    thread = threading.Thread(target=robot)
    thread.start()
    deadline = time.monotonic() + 15
    while app.state.service.job_watch.waiting < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert app.state.service.job_watch.waiting == 1
    client.portal.call(app.state.service.job_watch.release_all)  # what the server's shutdown calls
    thread.join(15)
    ((seconds, job),) = answers
    assert job["status"] == "queued" and seconds < 15  # not the whole 20 s wait
    # a request that comes during the shutdown does not wait either
    assert client.get(f"/v1/jobs/{job_id}", params={"wait": 20}).json()["status"] == "queued"


def test_jobs_are_listed_a_page_at_a_time_and_filtered(client, worker, dataset, sample):
    vectors = unused_vectors(dataset, 3)
    ids = {}
    for i, name in enumerate(("a", "b", "c")):
        r = client.post("/v1/classes", json={"name": name, "attribute_vector": vectors[i]})
        ids[name] = (r.json()["class"]["id"], r.json()["job"]["id"])
    r = client.post(f"/v1/classes/{ids['a'][0]}/samples", json={"sample": sample})
    sample_job = r.json()["job"]["id"]
    client.delete(f"/v1/classes/{ids['c'][0]}")  # c's registration will fail: withdrawn first
    worker.run_once()

    first = client.get("/v1/jobs", params={"limit": 2}).json()
    rest = client.get("/v1/jobs", params={"after": first["next_after"]}).json()
    everything = first["jobs"] + rest["jobs"]
    assert [j["id"] for j in everything] == sorted(j["id"] for j in everything) and len(
        everything
    ) == 5
    assert rest["next_after"] is None

    failed = client.get("/v1/jobs", params={"status": "failed"}).json()["jobs"]
    assert [(j["id"], j["kind"]) for j in failed] == [(ids["c"][1], "register_class")]
    assert "was withdrawn" in failed[0]["error"]
    of_a = client.get("/v1/jobs", params={"class_id": ids["a"][0]}).json()["jobs"]
    assert [j["id"] for j in of_a] == [ids["a"][1], sample_job]
    samples = client.get("/v1/jobs", params={"kind": "add_sample", "status": "succeeded"}).json()[
        "jobs"
    ]
    assert [j["id"] for j in samples] == [sample_job]
    for bad in ({"status": "done"}, {"kind": "delete"}, {"class_id": 0}):
        r = client.get("/v1/jobs", params=bad)
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, bad
        assert r.json()["errors"][0]["field"] == next(iter(bad))
