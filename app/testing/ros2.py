"""A real ``tactile-zsl ros2`` process and a ROS 2 node that talks to it over DDS, for the
tests (tests/ros2) and bench/ros2.py. Discovery stays on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) in a domain chosen at random, so no traffic
leaves it and runs beside each other do not hear each other."""

from __future__ import annotations

import json
import os
import queue
import random
import subprocess
import threading
import time
import uuid
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.testing.harness import serving as serving  # re-exported for tests/ros2
from app.testing.harness import tactile_zsl

READY_TIMEOUT = 60.0


def local_ros_environment(domain_id: int | None = None) -> int:
    """Keep ROS 2 discovery on this machine, in ``domain_id`` (random in 1-100 when None);
    call before rclpy initialises. Child processes inherit it. Returns the domain."""
    domain = random.randint(1, 100) if domain_id is None else domain_id
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    return domain


class RosClient:
    """rclpy, initialised, and one node spun in a thread: the robot's side. Its callbacks
    run in that thread, between waits; ``destroy`` hands publishers and subscriptions to it
    to destroy there (rclpy's executor fails on one destroyed while it waits on it)."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f"robot_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._doomed: queue.Queue[Any] = queue.Queue()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.subscription import Subscription

        while not self._stopping.is_set():
            self.executor.spin_once(timeout_sec=0.02)
            while not self._doomed.empty():
                entity, done = self._doomed.get()
                destroy = (
                    self.node.destroy_subscription
                    if isinstance(entity, Subscription)
                    else self.node.destroy_publisher
                )
                destroy(entity)
                done.set()

    def destroy(self, *entities: Any) -> None:
        """Destroy publishers and subscriptions of ``node`` in the spinning thread."""
        for entity in entities:
            done = threading.Event()
            self._doomed.put((entity, done))
            done.wait(10)

    def close(self) -> None:
        self._stopping.set()
        self._thread.join(10)
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


@dataclass
class Answer:
    body: dict[str, Any]
    received: float  # time.perf_counter() when it arrived


class BridgeProcess:
    """``tactile-zsl ros2 *args`` in a namespace of its own, and this side's publishers and
    subscriptions of its topics. ``log`` gets the process's output."""

    def __init__(
        self,
        client: RosClient,
        args: Iterable[str],
        log: Path,
        params: dict[str, Any] | None = None,
    ) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from std_msgs.msg import Float32MultiArray, String

        from app.ros2 import topics

        self.client = client
        self.namespace = f"/robot_{uuid.uuid4().hex[:8]}"
        self.prefix = f"{self.namespace}/tactile_zsl"
        ros_args = ["--ros-args", "-r", f"__ns:={self.namespace}"]
        for name, value in (params or {}).items():
            ros_args += ["-p", f"{name}:={value}"]
        self.log = log
        with open(log, "wb") as out:
            self.popen = subprocess.Popen(
                [*tactile_zsl(), "ros2", *args, *ros_args], stdout=out, stderr=subprocess.STDOUT
            )
        node, reliable = client.node, topics.reliable_qos(1000)
        self.answers: queue.Queue[Answer] = queue.Queue()
        self.enrolments: queue.Queue[dict[str, Any]] = queue.Queue()
        self.diagnostics: dict[str, Any] = {}
        self._subs = [
            node.create_subscription(
                String, f"{self.prefix}/recognition", self._on_answer, reliable
            ),
            node.create_subscription(
                String,
                f"{self.prefix}/enrolment",
                lambda m: self.enrolments.put(json.loads(m.data)),
                reliable,
            ),
            node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 100),
        ]
        # a robot's publishers: reliable, which the bridge's best-effort inputs accept
        self.samples = node.create_publisher(Float32MultiArray, f"{self.prefix}/samples", reliable)
        self.frames = node.create_publisher(Float32MultiArray, f"{self.prefix}/frames", reliable)
        self.procedures = node.create_publisher(String, f"{self.prefix}/procedure", reliable)
        self.enrol_pub = node.create_publisher(String, f"{self.prefix}/enrol", reliable)

    def wait_ready(self, timeout: float = READY_TIMEOUT, model: bool = True) -> None:
        """Until every topic is matched both ways and (``model``) the diagnostics name the
        served model."""
        deadline = time.monotonic() + timeout
        node = self.client.node
        while time.monotonic() < deadline:
            assert self.popen.poll() is None, f"the bridge exited:\n{self.output()}"
            matched = (
                all(
                    p.get_subscription_count() > 0
                    for p in (self.samples, self.frames, self.procedures, self.enrol_pub)
                )
                and node.count_publishers(f"{self.prefix}/recognition") > 0
            )
            if matched and (not model or self.diagnostics.get("model_version")):
                time.sleep(0.2)  # the answers' reliable match settles on the bridge's side too
                return
            time.sleep(0.05)
        raise AssertionError(
            f"the bridge was not ready in {timeout} s (diagnostics {self.diagnostics}):\n"
            + self.output()
        )

    def publish_samples(self, x: Any) -> None:
        from app.ros2.arrays import multiarray

        self.samples.publish(multiarray(np.asarray(x, np.float32)))

    def publish_frame(self, frame: np.ndarray) -> None:
        from app.ros2.arrays import multiarray

        self.frames.publish(multiarray(frame, ("fingers", "channels")))

    def procedure(self, name: str) -> None:
        from std_msgs.msg import String

        self.procedures.publish(String(data=name))

    def enrol(self, body: dict[str, Any] | str) -> None:
        from std_msgs.msg import String

        self.enrol_pub.publish(String(data=body if isinstance(body, str) else json.dumps(body)))

    def next_answers(self, n: int, timeout: float = 60.0) -> list[Answer]:
        deadline = time.monotonic() + timeout
        out = []
        for _ in range(n):
            left = max(0.0, deadline - time.monotonic())
            try:
                out.append(self.answers.get(timeout=left))
            except queue.Empty:
                raise AssertionError(
                    f"{len(out)} of {n} answers came in {timeout} s:\n{self.output()}"
                ) from None
        return out

    def wait_diagnostics(self, condition, timeout: float = 30.0) -> dict[str, Any]:
        """The first diagnostics for which ``condition(values)`` holds."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.diagnostics and condition(self.diagnostics):
                return self.diagnostics
            time.sleep(0.05)
        raise AssertionError(f"diagnostics never met the condition: {self.diagnostics}")

    def output(self) -> str:
        return self.log.read_text(errors="replace")[-3000:]

    def stop(self) -> int:
        self.client.destroy(*self._subs, self.samples, self.frames, self.procedures, self.enrol_pub)
        self.popen.terminate()
        try:
            return self.popen.wait(20)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            return self.popen.wait()

    def _on_answer(self, msg: Any) -> None:
        self.answers.put(Answer(json.loads(msg.data), time.perf_counter()))

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith(self.prefix + ":"):
                values = {kv.key: kv.value for kv in status.values}
                self.diagnostics = {
                    **values,
                    "level": int.from_bytes(status.level, "little")
                    if isinstance(status.level, bytes)
                    else int(status.level),
                    "message": status.message,
                }


@dataclass
class Replay:
    """A replayed trial: the trials the bridge should answer (one per procedure), the
    frames published, and when each procedure's ``rest`` mark was published
    (``time.perf_counter()``)."""

    expected: list[dict[str, Any]]
    frames: int
    completed: list[float]


def replay_trial(
    bridge: BridgeProcess,
    trial: Any,
    procedures: tuple[str, ...],
    period: float,
    rest_frames: int = 100,
    pause: float = 0.0,
) -> Replay:
    """Publish a recorded ``RawTrial`` as a robot does: its frames every ``period`` seconds
    (0.01: the pilot's recorded rate), a procedure's name on ``~/procedure`` as its phase
    starts (the phases the project's ``PhaseRule`` finds in finger 0's pdc), ``rest`` as it
    ends, ``end`` after the last; 150 frames of rest lead in (``pause``: seconds of quiet
    around each mark; the bridge places marks by their stamps without it). Returns the
    trial as the bridge assembles it after each procedure (its JSON form, the bridge
    keeping ``rest_frames`` frames of rest): what it answers."""
    from app.ros2.arrays import fingers_of, frames_of

    frames = frames_of(trial)
    phases = trial.phase_bounds()[0]
    marks: dict[int, str] = {}
    for (start, end), name in zip(phases, procedures, strict=True):
        marks[start], marks[end] = name, "rest"
    first, last = max(0, phases[0][0] - 150), min(len(frames), phases[-1][1] + 10)
    due = time.perf_counter()
    completed = []  # when each procedure's closing mark went out
    for k in range(first, last):
        if k in marks:
            time.sleep(pause)
            bridge.procedure(marks[k])
            if marks[k] == "rest":
                completed.append(time.perf_counter())
            time.sleep(pause)
            due = time.perf_counter()
        bridge.publish_frame(frames[k])
        due += period
        if (wait := due - time.perf_counter()) > 0:
            time.sleep(wait)
    time.sleep(pause)
    bridge.procedure("end")
    origin = phases[0][0] - rest_frames
    expected = []
    for i, (_, end) in enumerate(phases):
        shifted = [[s - origin, e - origin] if j <= i else None for j, (s, e) in enumerate(phases)]
        fingers = [{k: v.tolist() for k, v in f.items()} for f in fingers_of(frames[origin:end])]
        expected.append({"fingers": fingers, "phases": shifted})
    return Replay(expected, last - first, completed)
