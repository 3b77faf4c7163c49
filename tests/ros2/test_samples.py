"""Samples over DDS: a real ``tactile-zsl ros2`` bridging a real ``tactile-zsl serve``, or
answering from the service's model file in process; every input gets the answer HTTP
gives for the same samples, in order, problems included."""

from __future__ import annotations

import io
import json
import socket
import threading
import time

import httpx
import numpy as np
import pytest
from std_msgs.msg import Float32MultiArray, MultiArrayDimension

from app.client import TactileClient
from app.testing.harness import free_port
from app.testing.service import names_of, quick_dataset, unused_vectors

pytestmark = pytest.mark.slow

WARN, ERROR = 1, 2  # diagnostic_msgs/DiagnosticStatus levels


def http_answer(url: str, samples: np.ndarray) -> dict:
    """POST /v1/recognize's body (answer or problem) for ``samples`` sent as .npy."""
    body = io.BytesIO()
    np.save(body, np.asarray(samples, np.float32))
    r = httpx.post(
        f"{url}/v1/recognize",
        content=body.getvalue(),
        headers={"Content-Type": "application/x-npy"},
        timeout=60,
    )
    return r.json()


def inputs(shape: tuple[int, ...], n_procedures: int) -> list[np.ndarray]:
    """What a robot sends: single samples, one lacking procedures (NaN blocks), a batch,
    a broken sensor (zeros, one dead channel: answers that abstain), and bad ones: another
    shape, infinity, NaN in part of a procedure."""
    x = quick_dataset().samples.astype(np.float32)
    rng = np.random.default_rng(7)
    touched = x[[0, 13, 27]] + rng.normal(0, 0.05, (3, *shape)).astype(np.float32)
    rows = shape[0] // n_procedures
    partial = touched[1].copy()
    partial[rows:] = np.nan  # only the first procedure done
    infinite = touched[0].copy()
    infinite[0, 0] = np.inf
    torn = touched[2].copy()
    torn[rows, :3] = np.nan  # part of a procedure missing: not a procedure not done
    dead = touched[2].copy()
    dead[4] = 0.0  # one dead channel
    return [
        touched[0],
        touched[1],
        partial,
        x[40:43],
        touched[2],
        np.zeros(shape, np.float32),
        dead,
        np.zeros(3, np.float32),
        infinite,
        torn,
    ]


def test_each_sample_gets_the_answer_http_gives_in_order(samples_service, bridge_factory):
    active = httpx.get(f"{samples_service}/v1/models/active").json()
    shape, procedures = tuple(active["input_shape"]), active["procedures"]
    bridge = bridge_factory("--url", samples_service)
    sent = inputs(shape, len(procedures))
    for x in sent:
        bridge.publish_samples(x)
    flat = Float32MultiArray(data=sent[0].ravel().tolist())  # no layout: the model's shape
    bridge.samples.publish(flat)
    answers = [a.body for a in bridge.next_answers(len(sent) + 1)]

    assert answers == [http_answer(samples_service, x) for x in [*sent, sent[0]]]
    assert [len(a.get("results", [])) for a in answers] == [1, 1, 1, 3, 1, 1, 1, 0, 0, 0, 1]
    assert answers[2]["results"][0]["procedures_used"] == [procedures[0]]
    assert answers[2]["results"][0]["next_procedure"] in procedures[1:]
    for broken in answers[5:7]:  # a broken sensor is not answered as an object
        (result,) = broken["results"]
        assert result["kind"] == "input_outlier" and result["class_name"] is None
    assert answers[4]["results"][0]["kind"] != "input_outlier"
    for problem in answers[7:10]:
        assert problem["status"] == 422 and problem["errors"][0]["field"] == "samples"

    # a layout that its values do not fill has no HTTP twin; it is a 422 all the same
    torn = Float32MultiArray(data=[1.0] * 10)
    torn.layout.dim = [MultiArrayDimension(label="rows", size=4, stride=4)]
    bridge.samples.publish(torn)
    (answer,) = bridge.next_answers(1)
    assert answer.body["status"] == 422 and "layout.dim gives shape [4]" in answer.body["detail"]

    diagnostics = bridge.wait_diagnostics(lambda d: d["answered"] == str(len(sent) + 2))
    assert diagnostics["level"] == 0 and diagnostics["reachable"] == "true"
    assert diagnostics["model_version"] == str(active["version"])
    assert float(diagnostics["latency_p50_ms"]) > 0


def test_a_model_file_answers_as_the_service_and_is_read_again_after_an_enrolment(
    samples_service, bridge_factory, tmp_path
):
    model_file = tmp_path / "robot.bundle"
    with TactileClient(samples_service, model_file=model_file) as client:
        assert client.sync_model()
    active = httpx.get(f"{samples_service}/v1/models/active").json()
    shape, procedures = tuple(active["input_shape"]), active["procedures"]
    offline = bridge_factory("--model", str(model_file))
    online = bridge_factory("--url", samples_service)
    sent = inputs(shape, len(procedures))
    for x in sent:
        offline.publish_samples(x)
    answers = [a.body for a in offline.next_answers(len(sent))]
    assert answers == [http_answer(samples_service, x) for x in sent]

    # enrolments need the service: the model file's bridge says so
    dataset = quick_dataset()
    body = {"name": "ros-enrolled", "attributes": names_of(unused_vectors(dataset, 1)[0], dataset)}
    offline.enrol(body)
    refused = offline.enrolments.get(timeout=30)
    assert refused["status"] == 503 and "--url" in refused["detail"]

    # malformed and refused enrolments get their problem; a good one its finished job
    online.enrol("{not json")
    malformed = online.enrolments.get(timeout=30)
    assert malformed["status"] == 422 and malformed["errors"][0]["field"] == "body"
    online.enrol({"name": "", "attributes": ["hard"]})
    refused = online.enrolments.get(timeout=30)
    direct = httpx.post(f"{samples_service}/v1/classes", json={"name": "", "attributes": ["hard"]})
    assert direct.status_code == 422 and refused == direct.json()
    online.enrol(body)
    job = online.enrolments.get(timeout=300)
    assert job["status"] == "succeeded", job
    assert job["model_version"] > active["version"]
    names = [c["name"] for c in httpx.get(f"{samples_service}/v1/classes").json()["classes"]]
    assert "ros-enrolled" in names

    # the robot syncs its model file; the bridge reads it again at its next answer
    sidecar = model_file.with_name(model_file.name + ".json")
    with TactileClient(samples_service, model_file=model_file) as client:
        deadline = time.monotonic() + 30
        while (
            client.sync_model() or json.loads(sidecar.read_text())["version"] < job["model_version"]
        ):
            assert time.monotonic() < deadline, "the service never served the new version"
            time.sleep(0.5)
    offline.publish_samples(sent[0])
    (after,) = offline.next_answers(1)
    assert after.body == http_answer(samples_service, sent[0])
    assert after.body["model_version"] >= job["model_version"]
    offline.wait_diagnostics(lambda d: d["model_version"] == str(after.body["model_version"]))

    # a replacement that cannot be read: the model read before answers on, with a warning
    broken = tmp_path / "broken.bundle"
    broken.write_bytes(b"not a bundle")
    broken.replace(model_file)
    offline.publish_samples(sent[0])
    (still,) = offline.next_answers(1)
    assert still.body == after.body
    warned = offline.wait_diagnostics(lambda d: d["level"] == WARN)
    assert "cannot be read" in warned["message"]


class SlowProxy:
    """A TCP proxy on ``port`` to ``target``, holding each answer ``delay`` seconds: a
    slow service, or, before ``open()``, none at all."""

    def __init__(self, port: int, target: int, delay: float = 0.0) -> None:
        self.port, self.target, self.delay = port, target, delay
        self._server: socket.socket | None = None

    def open(self) -> SlowProxy:
        self._server = socket.create_server(("127.0.0.1", self.port))
        threading.Thread(target=self._accept, daemon=True).start()
        return self

    def close(self) -> None:
        if self._server is not None:
            self._server.close()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            upstream = socket.create_connection(("127.0.0.1", self.target))
            threading.Thread(target=self._pipe, args=(client, upstream, 0.0), daemon=True).start()
            threading.Thread(
                target=self._pipe, args=(upstream, client, self.delay), daemon=True
            ).start()

    @staticmethod
    def _pipe(src: socket.socket, dst: socket.socket, delay: float) -> None:
        try:
            while data := src.recv(65536):
                time.sleep(delay)
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                s.close()


def test_a_service_down_is_an_error_and_the_bridge_reconnects(samples_service, bridge_factory):
    port = free_port()
    bridge = bridge_factory(
        "--url", f"http://127.0.0.1:{port}", "--timeout", "2", ready=True, model=False
    )
    bridge.wait_diagnostics(lambda d: d["level"] == ERROR and d["reachable"] == "false")
    sample = quick_dataset().samples[0]
    bridge.publish_samples(sample)
    (down,) = bridge.next_answers(1)
    assert down.body["status"] == 503 and "cannot be reached" in down.body["detail"]

    proxy = SlowProxy(port, int(samples_service.rsplit(":", 1)[1])).open()
    try:
        bridge.wait_diagnostics(lambda d: d["level"] == 0 and d["model_version"], timeout=60)
        bridge.publish_samples(sample)
        (up,) = bridge.next_answers(1)
        assert up.body == http_answer(samples_service, sample)
    finally:
        proxy.close()


def test_a_full_queue_answers_each_input_in_its_place(samples_service, bridge_factory):
    port = free_port()
    proxy = SlowProxy(port, int(samples_service.rsplit(":", 1)[1]), delay=0.5).open()
    try:
        bridge = bridge_factory("--url", f"http://127.0.0.1:{port}", params={"queue_size": 2})
        samples = quick_dataset().samples[:8]
        for x in samples:
            bridge.publish_samples(x)
        answers = [a.body for a in bridge.next_answers(len(samples), timeout=120)]
    finally:
        proxy.close()
    refused = [i for i, a in enumerate(answers) if a.get("status") == 503]
    kept = [i for i in range(len(samples)) if i not in refused]
    assert len(kept) >= 2 and len(refused) >= 4, answers
    # the first inputs fill the queue; later ones are refused while it is full, and one may
    # find a place freed meanwhile (the proxy delays each answer by 0.5 s, not forever)
    assert kept[:2] == [0, 1], answers
    assert all("queue of 2 inputs was full" in answers[i]["detail"] for i in refused)
    for i in kept:
        assert answers[i] == http_answer(samples_service, samples[i])
    diagnostics = bridge.wait_diagnostics(lambda d: d["answered"] == str(len(samples)))
    assert diagnostics["refused_queue_full"] == str(len(refused))
