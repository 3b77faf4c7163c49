"""End to end: real ``tactile-zsl serve --no-worker`` and ``tactile-zsl worker`` processes
on a free port walk a robot's session, are restarted, and have lost nothing."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl
from app.testing.service import QUICK_DATASET, QUICK_METHOD, QUICK_PARAMS, list_all, quick_dataset

pytestmark = pytest.mark.slow

JOB_TIMEOUT = 180


class Service:
    """The two processes, their logs in the data folder."""

    def __init__(self, data_dir: Path, port: int) -> None:
        self.data_dir, self.port = data_dir, port
        self.env = {
            **os.environ,
            "TACTILE_DATA_DIR": str(data_dir),
            "TACTILE_DATASET": QUICK_DATASET,
            "TACTILE_METHOD": QUICK_METHOD,
            "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
            "TACTILE_MODEL_POLL_SECONDS": "0.2",
            "TACTILE_WORKER_POLL_SECONDS": "0.1",
        }
        self.procs: list[subprocess.Popen] = []
        self.starts = itertools.count()

    def start(self) -> None:
        n = next(self.starts)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        for name, args in (
            ("serve", ["serve", "--no-worker", "--port", str(self.port)]),
            ("worker", ["worker"]),
        ):
            log = open(self.data_dir / f"{name}-{n}.log", "wb")  # noqa: SIM115 - closed with the process
            self.procs.append(
                subprocess.Popen(
                    [*tactile_zsl(), *args],
                    env=self.env,
                    cwd=self.data_dir,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )

    def stop(self) -> None:
        for p in self.procs:
            p.send_signal(signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(60)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.procs = []

    def wait_ready(self, client: httpx.Client) -> None:
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while time.monotonic() < deadline:
            for p in self.procs:
                assert p.poll() is None, f"a process exited with {p.returncode}:\n{self.logs()}"
            try:
                if client.get("/readyz").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.5)
        raise AssertionError(f"service not ready after {STARTUP_TIMEOUT}s:\n{self.logs()}")

    def logs(self) -> str:
        return "\n".join(
            f"--- {f.name}\n{f.read_text(errors='replace')[-3000:]}"
            for f in sorted(self.data_dir.glob("*.log"))
        )


def wait_job(client: httpx.Client, job_id: int, service: Service, served: bool = True) -> dict:
    """The job once finished; with ``served``, once the process behind ``client``'s
    connection serves the version it made too (the job's answer does not wait for that)."""
    deadline = time.monotonic() + JOB_TIMEOUT
    while time.monotonic() < deadline:  # the way a robot waits: one long poll at a time
        job = client.get(f"/v1/jobs/{job_id}", params={"wait": 10}, timeout=30).json()
        if job["status"] in ("succeeded", "failed"):
            version = job.get("model_version") if served else None
            while version is not None and time.monotonic() < deadline:
                if (client.get("/readyz").json().get("model_version") or 0) >= version:
                    return job
                time.sleep(0.1)
            if version is None:
                return job
    raise AssertionError(f"job {job_id} not done after {JOB_TIMEOUT}s:\n{service.logs()}")


def snapshot(client: httpx.Client) -> dict:
    return {
        "classes": list_all(client, "/v1/classes", "classes"),
        "models": list_all(client, "/v1/models", "models"),
        "attributes": client.get("/v1/attributes").json()["attributes"],
    }


def test_robot_session_survives_a_restart(tmp_path):
    samples = quick_dataset().samples
    rng = np.random.default_rng(1)
    service = Service(tmp_path / "data", free_port())
    service.start()  # both at once: only one of them may bootstrap
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{service.port}", timeout=30) as client:
            service.wait_ready(client)

            # a robot recognises what it touches
            r = client.post("/v1/recognize", json={"samples": samples[:2].tolist()})
            assert r.status_code == 200, r.text
            assert r.json()["model_version"] == 1

            # an operator registers a never-touched object by its attributes
            attributes = client.get("/v1/attributes").json()["attributes"]
            taken = {tuple(c["attributes"]) for c in list_all(client, "/v1/classes", "classes")}
            names = next(
                [a, b] for a, b in itertools.combinations(attributes, 2) if (a, b) not in taken
            )
            r = client.post("/v1/classes", json={"name": "teapot", "attributes": names})
            assert r.status_code == 202, r.text
            teapot = r.json()["class"]["id"]
            job = wait_job(client, r.json()["job"]["id"], service, served=False)
            assert job["status"] == "succeeded", job

            # the robot touches it: recognised by the model that includes it, which the
            # process that answers loads first if it has not yet
            touch = samples[0] + rng.normal(0, 0.05, samples[0].shape).astype(np.float32)
            r = client.post(
                "/v1/recognize",
                params={"min_model_version": job["model_version"]},
                json={"samples": [touch.tolist()]},
            )
            assert r.status_code == 200 and r.json()["model_version"] >= job["model_version"]
            assert client.get(f"/v1/classes/{teapot}").json()["in_active_model"] is True

            # and adds the real sample (one-shot)
            r = client.post(f"/v1/classes/{teapot}/samples", json={"sample": touch.tolist()})
            assert r.status_code == 202, r.text
            job = wait_job(client, r.json()["job"]["id"], service)
            assert job["status"] == "succeeded", job
            before = snapshot(client)
            assert before["models"][-1]["active"] and len(before["models"]) == 3

            # before it drives out of the network, the robot takes the active model along
            # and recognises offline with the same answers
            version = client.get("/v1/models/active").json()["version"]
            r = client.get(f"/v1/models/{version}/bundle")
            assert r.status_code == 200, r.text
            (tmp_path / "robot.bundle").write_bytes(r.content)
            np.save(tmp_path / "touches.npy", np.stack([touch, samples[3]]))
            online = client.post(
                "/v1/recognize", json={"samples": [touch.tolist(), samples[3].tolist()]}
            )
            offline = subprocess.run(
                [
                    *tactile_zsl(),
                    "recognize",
                    "--model",
                    str(tmp_path / "robot.bundle"),
                    str(tmp_path / "touches.npy"),
                ],
                capture_output=True,
                text=True,
                timeout=120,
            )
            assert offline.returncode == 0, offline.stderr
            assert [a["class_name"] for a in json.loads(offline.stdout)["results"]] == [
                a["class_name"] for a in online.json()["results"]
            ]
            assert (
                client.get(
                    f"/v1/models/{version}/bundle", headers={"If-None-Match": r.headers["etag"]}
                ).status_code
                == 304
            )
            assert [c for c in before["classes"] if c["id"] == teapot][0]["n_samples"] == 1

        service.stop()
        service.start()
        with httpx.Client(base_url=f"http://127.0.0.1:{service.port}", timeout=30) as client:
            service.wait_ready(client)
            after = snapshot(client)
            assert after == before  # every class, sample count and model version still there
            r = client.post("/v1/recognize", json={"samples": [touch.tolist()]})
            assert r.json()["model_version"] == before["models"][-1]["version"]
            assert "base model stored" not in (service.data_dir / "serve-1.log").read_text()

            # the sample was of the wrong object after all: withdrawn, the model retrained
            # without it
            sample_id = job["sample_id"]
            r = client.delete(f"/v1/classes/{teapot}/samples/{sample_id}")
            assert r.status_code == 202, r.text
            job = wait_job(client, r.json()["job"]["id"], service)
            assert job["status"] == "succeeded", job
            active = client.get("/v1/models/active").json()
            assert active["version"] == job["model_version"] and active["reason"] == "withdrawal"
            teapot_now = client.get(f"/v1/classes/{teapot}").json()
            assert teapot_now["n_samples"] == 0 and teapot_now["in_active_model"] is True

            # and the operator's description missed an attribute: corrected, the model follows
            taken = {tuple(c["attributes"]) for c in list_all(client, "/v1/classes", "classes")}
            fixed = next(
                f
                for a in attributes
                if a not in names
                and tuple(f := sorted([*names, a], key=attributes.index)) not in taken
            )
            r = client.patch(f"/v1/classes/{teapot}", json={"attributes": fixed})
            assert r.status_code == 202, r.text
            job = wait_job(client, r.json()["job"]["id"], service)
            assert job["status"] == "succeeded", job
            assert client.get("/v1/models/active").json()["reason"] == "update"
            assert client.get(f"/v1/classes/{teapot}").json()["attributes"] == fixed
    finally:
        service.stop()


def test_a_lab_starts_empty_and_grows_its_own_vocabulary(tmp_path):
    """A real ``serve`` started without a dataset: attributes added over HTTP, classes
    registered with their touches, the first model trained, an attribute added later
    learnt, one retired."""
    touches = quick_dataset()
    service = Service(tmp_path / "data", free_port())
    service.env.update({"TACTILE_DATASET": "none", "TACTILE_METHOD": "best"})
    service.env.pop("TACTILE_METHOD_PARAMS")
    service.start()
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{service.port}", timeout=30) as client:
            service.wait_ready(client)
            ready = client.get("/readyz").json()
            assert "model_version" not in ready and "0 so far" in ready["detail"], ready
            r = client.post("/v1/recognize", json={"samples": touches.samples[:1].tolist()})
            assert r.status_code == 409 and "0 so far" in r.json()["detail"], r.text
            assert client.post("/v1/attributes", json={"name": "soft"}).status_code == 202
            jobs = []
            for k, (name, soft) in enumerate((("sponge", 1), ("stone", 0), ("felt", 0.5))):
                body = {
                    "name": name,
                    "samples": touches.samples[touches.labels == k][:3].tolist(),
                    "attributes": {"soft": soft} if soft else None,
                }
                r = client.post("/v1/classes", json={k: v for k, v in body.items() if v})
                assert r.status_code == 202, r.text
                jobs.append(r.json()["job"]["id"])
            assert all(wait_job(client, j, service)["status"] == "succeeded" for j in jobs)
            r = client.post("/v1/recognize", json={"samples": touches.samples[:1].tolist()})
            assert r.status_code == 200, r.text
            r = client.post(
                "/v1/attributes",
                json={"name": "cold", "values": {"stone": 1, "sponge": 0}},
            )
            assert r.status_code == 202, r.text
            assert wait_job(client, r.json()["job"]["id"], service)["status"] == "succeeded"
            active = client.get("/v1/models/active").json()
            assert active["attribute_names"] == ["soft", "cold"], active
            r = client.post("/v1/describe", json={"samples": touches.samples[:1].tolist()})
            assert {a["name"] for a in r.json()["results"][0]["attributes"]} == {"soft", "cold"}
            r = client.delete("/v1/attributes/cold")
            assert r.status_code == 202, r.text
            assert wait_job(client, r.json()["job"]["id"], service)["status"] == "succeeded"
            assert client.get("/v1/models/active").json()["attribute_names"] == ["soft"]
    finally:
        service.stop()


def test_a_robot_touches_procedure_by_procedure_as_the_service_asks(tmp_path):
    """A real ``serve`` of ``best`` on the simulator: the robot starts with the model's
    first procedure and sends the sample again, procedure by procedure, as each answer's
    next_procedure asks, until it is null."""
    from app.framework.recognizer import MIN_PROCEDURES
    from app.testing.service import BEST_PARAMS

    dataset = quick_dataset()
    rng = np.random.default_rng(2)
    # a touch unlike the training ones: the forest is not sure of it after one procedure
    touch = dataset.samples[3] + rng.normal(0, dataset.samples.std(), dataset.input_shape)
    rows = touch.shape[0] // len(dataset.procedures)
    service = Service(tmp_path / "data", free_port())
    service.env.update(
        TACTILE_METHOD="best", TACTILE_METHOD_PARAMS=json.dumps({"best": BEST_PARAMS})
    )
    service.start()
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{service.port}", timeout=30) as client:
            service.wait_ready(client)
            active = client.get("/v1/models/active").json()
            assert active["procedures"] == list(dataset.procedures)
            for target, most in ((1.0, 4), (1e-6, MIN_PROCEDURES)):
                sample: list = [None] * touch.shape[0]
                name, done = active["first_procedure"], []
                while name is not None:
                    j = dataset.procedures.index(name)
                    sample[j * rows : (j + 1) * rows] = touch[j * rows : (j + 1) * rows].tolist()
                    done.append(name)
                    r = client.post(
                        "/v1/recognize",
                        # the touch is noisier than any training one, an input outlier:
                        # the model's guess is asked for, since procedures are tested here
                        params={"target_confidence": target, "outliers": "answer"},
                        json={"samples": [sample]},
                    )
                    assert r.status_code == 200, r.text
                    (answer,) = r.json()["results"]
                    assert answer["procedures_used"] == [p for p in dataset.procedures if p in done]
                    name = answer["next_procedure"]
                    assert name not in done
                assert len(done) == most  # never sure: all four; sure at once: two
            assert answer["class_name"] in dataset.class_names, answer
    finally:
        service.stop()
