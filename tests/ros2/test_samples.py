"""Samples over DDS: a real ``tactile-zsl ros2`` bridging a real ``tactile-zsl serve``, or
answering from the service's model file in process; every input gets the answer HTTP
gives for the same samples, in order, problems included."""

from __future__ import annotations

import contextlib
import io
import json
import socket
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from std_msgs.msg import Float32MultiArray, MultiArrayDimension

from app.client import TactileClient
from app.testing.harness import free_port
from app.testing.service import names_of, quick_dataset, unused_vectors

pytestmark = pytest.mark.slow

WARN, ERROR = 1, 2  # diagnostic_msgs/DiagnosticStatus levels


def http_answer(url: str, samples: np.ndarray, **params) -> dict:
    """POST /v1/recognize's body (answer or problem) for ``samples`` sent as .npy."""
    body = io.BytesIO()
    np.save(body, np.asarray(samples, np.float32))
    r = httpx.post(
        f"{url}/v1/recognize",
        content=body.getvalue(),
        headers={"Content-Type": "application/x-npy"},
        params=params,
        timeout=60,
    )
    return r.json()


def split(url: str, x: np.ndarray, shape: tuple[int, ...]) -> list[dict]:
    """What the bridge answers for ``x``: HTTP's answer, one per sample of a message that
    held several."""
    body = http_answer(url, x)
    if np.ndim(x) == len(shape) + 1 and "results" in body:
        return [{**body, "results": [r]} for r in body["results"]]
    return [body]


def without_input(answers) -> list[dict]:
    return [{k: v for k, v in a.body.items() if k != "input"} for a in answers]


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
    got = bridge.next_answers(len(sent) + 3)  # the message of three: an answer each
    # HTTP's answers once the bridge's are in: the service batches concurrent requests
    expected = [split(samples_service, x, shape) for x in [*sent, sent[0]]]
    answers = without_input(got)

    # a message of three samples gets an answer per sample, each naming its index
    assert answers == [a for each in expected for a in each]
    named = [(a.body["input"]["sequence"], a.body["input"]["index"]) for a in got]
    assert named == [(1, None), (2, None), (3, None), (4, 0), (4, 1), (4, 2)] + [
        (k, None) for k in range(5, len(sent) + 2)
    ]
    assert all(a.body["input"]["stamp"]["sec"] > 0 for a in got)
    del answers[4:6]  # the batch's answers, one kept
    assert [len(a.get("results", [])) for a in answers] == [1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1]
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
    assert answer.body["input"]["sequence"] == len(sent) + 2

    diagnostics = bridge.wait_diagnostics(lambda d: d["answered"] == str(len(sent) + 4))
    assert diagnostics["samples_missing"] == "0"
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
    expected = [a for x in sent for a in split(samples_service, x, shape)]
    assert without_input(offline.next_answers(len(expected))) == expected

    # enrolments need the service: the model file's bridge says so
    dataset = quick_dataset()
    body = {"name": "ros-enrolled", "attributes": names_of(unused_vectors(dataset, 1)[0], dataset)}
    offline.enrol(body)
    refused = offline.enrolments.get(timeout=30)
    assert refused["status"] == 503 and "--url" in refused["detail"]

    # each enrolment gets its answer in the order they came: problems that need no
    # service do not overtake an enrolment still waiting for its model
    online.enrol(body)
    online.enrol("{not json")
    online.enrol({"name": "", "attributes": ["hard"]})
    job, malformed, refused = (online.enrolments.get(timeout=300) for _ in range(3))
    assert [e["input"]["sequence"] for e in (job, malformed, refused)] == [1, 2, 3]
    assert malformed["status"] == 422 and malformed["errors"][0]["field"] == "body"
    direct = httpx.post(f"{samples_service}/v1/classes", json={"name": "", "attributes": ["hard"]})
    del refused["input"]
    assert direct.status_code == 422 and refused == direct.json()
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
    (after,) = without_input(offline.next_answers(1))
    assert after == http_answer(samples_service, sent[0])
    assert after["model_version"] >= job["model_version"]
    offline.wait_diagnostics(lambda d: d["model_version"] == str(after["model_version"]))

    # a replacement that cannot be read: the model read before answers on, with a warning
    broken = tmp_path / "broken.bundle"
    broken.write_bytes(b"not a bundle")
    broken.replace(model_file)
    offline.publish_samples(sent[0])
    (still,) = without_input(offline.next_answers(1))
    assert still == after
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
        (up,) = without_input(bridge.next_answers(1))
        assert up == http_answer(samples_service, sample)
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
        got = bridge.next_answers(len(samples), timeout=120)
    finally:
        proxy.close()
    # every answer, refusals included, names the message it answers, in order
    assert [a.body["input"]["sequence"] for a in got] == list(range(1, len(samples) + 1))
    answers = without_input(got)
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


def call(ros, service_type, name: str, request, timeout: float = 20.0):
    """Call the bridge's ROS service ``name`` from the robot's node; its response."""
    client = ros.node.create_client(service_type, name)
    assert client.wait_for_service(timeout_sec=timeout), f"no service {name}"
    future = client.call_async(request)
    deadline = time.monotonic() + timeout
    while not future.done():
        assert time.monotonic() < deadline, f"{name} did not answer"
        time.sleep(0.02)
    return future.result()


def set_parameters(ros, bridge, **values) -> list:
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    request = SetParameters.Request(
        parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
    )
    return call(ros, SetParameters, f"{bridge.prefix}/set_parameters", request).results


def test_a_parameter_changed_at_run_time_takes_effect_at_the_next_answer(
    samples_service, bridge_factory, ros
):
    bridge = bridge_factory("--url", samples_service)
    sample = quick_dataset().samples[0]
    bridge.publish_samples(sample)
    (before,) = bridge.next_answers(1)
    assert before.body["results"][0]["known_kept"] != 0.5

    (changed,) = set_parameters(ros, bridge, known_kept=0.5)
    assert changed.successful, changed.reason
    bridge.publish_samples(sample)
    (after,) = without_input(bridge.next_answers(1))
    assert after["results"][0]["known_kept"] == 0.5
    assert after == http_answer(samples_service, sample, known_kept=0.5)
    bridge.wait_diagnostics(lambda d: d["known_kept"] == "0.5")

    # out of range, or fixed at the start: refused, naming why; the setting stays
    (bad,) = set_parameters(ros, bridge, known_kept=1.0)
    assert not bad.successful and "known_kept must lie in (0, 1)" in bad.reason
    (fixed,) = set_parameters(ros, bridge, queue_size=3)
    assert not fixed.successful
    bridge.publish_samples(sample)
    (still,) = without_input(bridge.next_answers(1))
    assert still["results"][0]["known_kept"] == 0.5


def test_the_shipped_parameter_file_names_every_parameter_with_its_default():
    import yaml

    from app.ros2.node import PARAMETERS

    shipped = Path(__file__).resolve().parents[2] / "docs" / "ros2_params.yaml"
    (section,) = yaml.safe_load(shipped.read_text()).values()
    values = section["ros__parameters"]
    assert values == {name: p.default for name, p in PARAMETERS.items()}


def test_a_parameter_file_sets_the_bridge_up(samples_service, bridge_factory, tmp_path):
    import yaml

    shipped = Path(__file__).resolve().parents[2] / "docs" / "ros2_params.yaml"
    settings = yaml.safe_load(shipped.read_text())
    (values,) = (s["ros__parameters"] for s in settings.values())
    values.update(url=samples_service, queue_size=3, known_kept=0.25)
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(settings))
    bridge = bridge_factory("--ros-args", "--params-file", str(params))
    diagnostics = bridge.wait_diagnostics(lambda d: d["queue"] == "0/3")
    assert diagnostics["known_kept"] == "0.25" and diagnostics["reachable"] == "true"
    sample = quick_dataset().samples[0]
    bridge.publish_samples(sample)
    (answer,) = without_input(bridge.next_answers(1))
    assert answer == http_answer(samples_service, sample, known_kept=0.25)


def test_a_lifecycle_bridge_answers_only_while_active_and_keeps_what_came_meanwhile(
    samples_service, bridge_factory, ros
):
    from lifecycle_msgs.msg import State, Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    def change(bridge, transition: int) -> bool:
        request = ChangeState.Request(transition=Transition(id=transition))
        return call(ros, ChangeState, f"{bridge.prefix}/change_state", request).success

    def state(bridge) -> int:
        return call(
            ros, GetState, f"{bridge.prefix}/get_state", GetState.Request()
        ).current_state.id

    # configure fails where the service cannot be reached; the node stays unconfigured
    down = bridge_factory("--url", f"http://127.0.0.1:{free_port()}", "--lifecycle", ready=False)
    assert state(down) == State.PRIMARY_STATE_UNCONFIGURED
    assert not change(down, Transition.TRANSITION_CONFIGURE)
    assert state(down) == State.PRIMARY_STATE_UNCONFIGURED

    bridge = bridge_factory("--url", samples_service, "--lifecycle", ready=False)
    assert state(bridge) == State.PRIMARY_STATE_UNCONFIGURED
    assert change(bridge, Transition.TRANSITION_CONFIGURE)
    bridge.wait_ready()
    samples = quick_dataset().samples[:3]
    bridge.publish_samples(samples[0])
    time.sleep(1.0)
    assert bridge.answers.empty(), "an inactive bridge answered"
    assert change(bridge, Transition.TRANSITION_ACTIVATE)
    (first,) = bridge.next_answers(1)
    assert first.body["input"]["sequence"] == 1

    assert change(bridge, Transition.TRANSITION_DEACTIVATE)
    for x in samples[1:]:
        bridge.publish_samples(x)
    time.sleep(1.0)
    assert bridge.answers.empty(), "a deactivated bridge answered"
    assert change(bridge, Transition.TRANSITION_ACTIVATE)
    kept = bridge.next_answers(2)
    assert [a.body["input"]["sequence"] for a in kept] == [2, 3]
    assert without_input(kept) == [http_answer(samples_service, x) for x in samples[1:]]
    assert state(bridge) == State.PRIMARY_STATE_ACTIVE


def test_the_readmes_rclpy_snippet_runs_against_a_real_bridge(samples_service, bridge_factory):
    import re
    import subprocess
    import sys

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme[readme.index("## ROS 2\n") : readme.index("## The API")]
    (snippet,) = re.findall(r"```python\n(.*?)```", section, re.S)
    bridge = bridge_factory("--url", samples_service)
    # the snippet's service and node, moved to this test's service and namespace
    code = snippet.replace("http://127.0.0.1:8000", samples_service).replace(
        '"/tactile_zsl"', repr(bridge.prefix)
    )
    assert code != snippet
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    sequence, _, results = out.stdout.strip().partition(" ")
    assert sequence == "1" and "class_name" in results, out.stdout


@contextlib.contextmanager
def stamped_publisher(ros, bridge):
    """A publisher on ``bridge``'s ``~/samples_stamped``, once the bridge subscribed."""
    from std_msgs.msg import String

    from app.ros2 import topics

    publisher = ros.node.create_publisher(
        String, f"{bridge.prefix}/samples_stamped", topics.reliable_qos(10)
    )
    try:
        deadline = time.monotonic() + 20
        while not publisher.get_subscription_count():
            assert time.monotonic() < deadline, "the bridge never subscribed"
            time.sleep(0.05)
        yield lambda body: publisher.publish(String(data=json.dumps(body)))
    finally:
        ros.destroy(publisher)


def test_stamped_samples_get_the_robots_header_echoed(samples_service, bridge_factory, ros):
    bridge = bridge_factory("--url", samples_service)
    with stamped_publisher(ros, bridge) as publish:
        x = quick_dataset().samples[:2].astype(np.float32)
        header = {"stamp": {"sec": 1700000000, "nanosec": 5}, "frame_id": "left_index_tip"}
        publish({"header": header, "samples": x[0].tolist()})
        publish({"header": header, "samples": x.tolist()})
        publish({"header": {"stamp": {"sec": 1}}, "samples": x[0].tolist()})
        got = bridge.next_answers(4)
    assert [a.body["input"].get("header") for a in got] == [header] * 3 + [None]
    assert [(a.body["input"]["sequence"], a.body["input"]["index"]) for a in got] == [
        (1, None),
        (2, 0),
        (2, 1),
        (3, None),
    ]
    expected = [*split(samples_service, x[0], x.shape[1:]), *split(samples_service, x, x.shape[1:])]
    assert without_input(got[:3]) == expected
    problem = got[3].body
    assert problem["status"] == 422 and problem["errors"][0]["field"] == "header"
    assert "header.stamp" in problem["detail"]


def test_a_table_on_stamped_samples_is_named_as_http_names_it(
    samples_service, bridge_factory, ros, tmp_path
):
    """A table over ROS 2: one ``~/samples_stamped`` message with ``objects``, one answer
    holding a result per object, as ``POST /v1/recognize`` gives it, from the service and
    from a model file; bad labels are the route's 422."""
    model_file = tmp_path / "robot.bundle"
    with TactileClient(samples_service, model_file=model_file) as client:
        assert client.sync_model()
    x = quick_dataset().samples[:6].astype(np.float32)
    objects = ["cup", 7, "cup", "box", 7, "box"]
    want = httpx.post(
        f"{samples_service}/v1/recognize", json={"samples": x.tolist(), "objects": objects}
    ).json()
    assert [r["object"] for r in want["results"]] == ["cup", 7, "box"]
    header = {"stamp": {"sec": 1700000000, "nanosec": 0}, "frame_id": "tray"}
    for args in (("--url", samples_service), ("--model", str(model_file))):
        bridge = bridge_factory(*args)
        with stamped_publisher(ros, bridge) as publish:
            for labels in (objects, objects[:2]):
                publish({"header": header, "samples": x.tolist(), "objects": labels})
            table, bad = bridge.next_answers(2)
        assert table.body["input"]["header"] == header and table.body["input"]["index"] is None
        got = without_input([table])[0]
        keys = ("object", "class_name", "kind", "alone", "touches", "is_novel")
        assert [{k: r[k] for k in keys} for r in got["results"]] == [
            {k: r[k] for k in keys} for r in want["results"]
        ], args
        np.testing.assert_allclose(
            [r["margin"] for r in got["results"]], [r["margin"] for r in want["results"]]
        )
        problem = bad.body
        assert problem["status"] == 422 and problem["errors"][0]["field"] == "objects"
        assert "2 labels for 6 samples" in problem["detail"], problem
