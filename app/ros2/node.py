"""The ``tactile_zsl`` node: samples and raw BioTac frames in, the service's answers out.

Subscription callbacks only read and queue (``AnswerQueue``); one worker thread answers the
queue in order through the backend and publishes each answer; a second thread runs
enrolments (they wait for the retrained model, minutes maybe), a third probes the backend
and publishes ``/diagnostics``. No input, fault or answer raises out of a callback or a
thread: what cannot be answered is answered with a problem.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections import deque
from typing import Any

import numpy as np
import orjson
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from std_msgs.msg import Float32MultiArray, String

from app.api.problems import problem_body
from app.ros2 import topics
from app.ros2.arrays import MessageShapeError, frame_of, samples_of
from app.ros2.backends import CLASSES, RECOGNIZE, Health, internal_problem
from app.ros2.queue import AnswerQueue, Work
from app.ros2.trials import MarkOrder, TrialAssembler, TrialProblem

NODE_NAME = "tactile_zsl"
log = logging.getLogger(__name__)

#: ROS parameters (``--ros-args -p name:=value``) and their defaults
PARAMETERS: dict[str, Any] = {
    "queue_size": 64,  # inputs waiting for an answer; beyond, each is answered with a 503
    "input_depth": 100,  # keep-last depth of the samples subscription
    "frame_depth": 10_000,  # of the raw frames subscription (100 s of a 100 Hz sensor)
    "answer_depth": 1000,  # of the answer publishers (reliable)
    "diagnostics_period": 1.0,  # seconds between /diagnostics messages
    "rest_frames": 100,  # frames before a trial's first procedure kept as its rest
    "max_trial_frames": 60_000,  # a trial longer than this is answered with a problem
    "enrol_queue_size": 16,  # enrolments waiting; beyond, each is answered with a 503
    "mark_wait": 1.0,  # seconds a procedure mark waits for a frame to place it (MarkOrder)
}
LATENCIES_KEPT = 1000


class TactileBridge(Node):
    """The node, answering through ``backend`` (``app.ros2.backends``). ``start`` its
    threads after construction and ``stop`` them before destroying it."""

    def __init__(self, backend: Any, **node_options: Any) -> None:
        super().__init__(NODE_NAME, **node_options)
        self.backend = backend
        for name, default in PARAMETERS.items():
            self.declare_parameter(name, default)
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.answers = AnswerQueue(int(p["queue_size"]))
        self.assembler = TrialAssembler(int(p["rest_frames"]), int(p["max_trial_frames"]))
        self.marks = MarkOrder(float(p["mark_wait"]))
        self.diagnostics_period = float(p["diagnostics_period"])
        self._enrolments: queue.Queue[dict[str, Any]] = queue.Queue(int(p["enrol_queue_size"]))
        self._latencies: deque[float] = deque(maxlen=LATENCIES_KEPT)
        self._counts = {"answered": 0, "frames": 0, "bad_frames": 0}
        self._health = Health(False, "not probed yet")
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []

        answer_qos = topics.reliable_qos(int(p["answer_depth"]))
        self.recognition = self.create_publisher(String, topics.RECOGNITION, answer_qos)
        self.enrolment = self.create_publisher(String, topics.ENROLMENT, answer_qos)
        self.diagnostics = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_subscription(
            Float32MultiArray,
            topics.SAMPLES,
            self._on_samples,
            topics.sensor_qos(int(p["input_depth"])),
        )
        self.create_subscription(
            Float32MultiArray,
            topics.FRAMES,
            self._on_frame,
            topics.sensor_qos(int(p["frame_depth"])),
        )
        self.create_subscription(
            String, topics.PROCEDURE, self._on_procedure, topics.reliable_qos(100)
        )
        self.create_subscription(String, topics.ENROL, self._on_enrol, topics.reliable_qos(100))
        self.create_timer(0.1, self._flush_marks)

    # ------------------------------------------------------------------ threads
    def start(self) -> TactileBridge:
        for target in (self._answer_loop, self._enrol_loop, self._health_loop):
            thread = threading.Thread(target=target, name=f"{NODE_NAME}{target.__name__}")
            thread.daemon = True  # a backend call stuck past stop() must not hold the exit
            thread.start()
            self._threads.append(thread)
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stopping.set()
        for thread in self._threads:
            thread.join(timeout)
        self.backend.close()

    # ---------------------------------------------------------------- callbacks
    def _on_samples(self, msg: Float32MultiArray) -> None:
        received = time.perf_counter()
        try:
            model = self.backend.model
            x = samples_of(msg, model.input_shape if model else None)
            work = Work("samples", x, received)
        except MessageShapeError as exc:
            work = Work("problem", _shape_problem(exc), received)
        except Exception:  # noqa: BLE001 - the input still gets its answer
            log.exception("reading a samples message")
            work = Work("problem", internal_problem(RECOGNIZE), received)
        self.answers.put(work)

    def _on_frame(self, msg: Float32MultiArray, info: dict[str, Any]) -> None:
        self._counts["frames"] += 1
        try:
            frame = frame_of(msg)
            for name in self.marks.frame(info["source_timestamp"], time.monotonic()):
                self._follow(name, 0, time.perf_counter())
            self.assembler.frame(frame)
        except MessageShapeError as exc:
            self._counts["bad_frames"] += 1
            self.assembler.fault(f"frame message {self._counts['frames']}: {exc}")
        except Exception:  # noqa: BLE001
            log.exception("reading a frame message")
            self.assembler.fault("a frame could not be read (the bridge's log has the details)")

    def _on_procedure(self, msg: String, info: dict[str, Any]) -> None:
        received = time.perf_counter()
        for name, late in self.marks.mark(msg.data, info["source_timestamp"]):
            self._follow(name, late, received)

    def _flush_marks(self) -> None:
        for name in self.marks.flush(time.monotonic()):
            self._follow(name, 0, time.perf_counter())

    def _follow(self, name: str, late: int, received: float) -> None:
        """Follow a procedure mark ``late`` frames back; queue the answer it calls for."""
        try:
            model = self.backend.model
            if model is None:
                detail = f"the model of {self.backend.source} is not known yet (not reached)"
                work = Work("problem", problem_body(503, detail, RECOGNIZE), received)
            else:
                trial = self.assembler.procedure(name, model.procedures, late)
                if trial is None:
                    return  # a trial's first procedure: nothing to answer yet
                work = Work("trial", trial, received)
        except TrialProblem as exc:
            work = Work("problem", exc.problem, received)
        except Exception:  # noqa: BLE001
            log.exception("following a procedure message")
            work = Work("problem", internal_problem(RECOGNIZE), received)
        self.answers.put(work)

    def _on_enrol(self, msg: String) -> None:
        try:
            body = json.loads(msg.data)
            if not isinstance(body, dict):
                raise ValueError("the message must hold a JSON object, POST /v1/classes's body")
        except ValueError as exc:
            detail = f"body: malformed JSON: {exc}"
            self._publish(
                self.enrolment,
                problem_body(422, detail, CLASSES, [{"field": "body", "reason": detail}]),
            )
            return
        try:
            self._enrolments.put_nowait(body)
        except queue.Full:
            detail = (
                f"the bridge's {self._enrolments.maxsize} enrolments waiting fill its queue; "
                "this one was not sent: publish it again later"
            )
            self._publish(self.enrolment, problem_body(503, detail, CLASSES))

    # -------------------------------------------------------------------- loops
    def _answer_loop(self) -> None:
        while not self._stopping.is_set():
            work = self.answers.get(timeout=0.2)
            if work is None:
                continue
            for _ in range(work.count):
                try:
                    body = self._answer(work)
                except Exception:  # noqa: BLE001 - the slot is answered whatever happens
                    log.exception("answering %s", work.kind)
                    body = internal_problem(RECOGNIZE)
                self._publish(self.recognition, body)
                self._latencies.append(time.perf_counter() - work.received)
                self._counts["answered"] += 1

    def _answer(self, work: Work) -> dict[str, Any]:
        if work.kind == "samples":
            return self.backend.recognize(work.payload)
        if work.kind == "trial":
            return self.backend.recognize_trial(work.payload)
        if work.kind == "refused":
            detail = (
                f"the bridge's queue of {self.answers.capacity} inputs was full (answers come "
                "slower than inputs): this input was not recognised"
            )
            return problem_body(503, detail, RECOGNIZE)
        return work.payload

    def _enrol_loop(self) -> None:
        while not self._stopping.is_set():
            try:
                body = self._enrolments.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                outcome = self.backend.enrol(body)
            except Exception:  # noqa: BLE001
                log.exception("enrolling")
                outcome = internal_problem(CLASSES)
            self._publish(self.enrolment, outcome)

    def _health_loop(self) -> None:
        while not self._stopping.is_set():
            try:
                self._health = self.backend.probe()
                self.diagnostics.publish(self.diagnostic_array())
            except Exception:  # noqa: BLE001
                log.exception("probing the backend")
            self._stopping.wait(self.diagnostics_period)

    # ------------------------------------------------------------------ helpers
    def _publish(self, publisher: Any, body: dict[str, Any]) -> None:
        publisher.publish(String(data=orjson.dumps(body).decode()))

    def diagnostic_array(self) -> DiagnosticArray:
        """The bridge's state: whether the backend answers, its model, queue and latency."""
        health = self._health
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: recognition")
        status.hardware_id = str(self.backend.source)
        waiting = len(self.answers)
        if not health.reachable:
            status.level, status.message = DiagnosticStatus.ERROR, health.message
        elif health.warning or waiting >= self.answers.capacity:
            status.level = DiagnosticStatus.WARN
            status.message = health.warning or "the answer queue is full"
        else:
            status.level, status.message = DiagnosticStatus.OK, health.message
        latencies = np.array(self._latencies) * 1e3
        model = health.model
        values = {
            "reachable": str(health.reachable).lower(),
            "model_version": str(model.version) if model else "",
            "input_kind": model.input_kind if model else "",
            "procedures": ",".join(model.procedures) if model else "",
            "queue": f"{waiting}/{self.answers.capacity}",
            "answered": str(self._counts["answered"]),
            "refused_queue_full": str(self.answers.refused),
            "frames": str(self._counts["frames"]),
            "bad_frames": str(self._counts["bad_frames"]),
            "latency_p50_ms": f"{np.percentile(latencies, 50):.2f}" if len(latencies) else "",
            "latency_p99_ms": f"{np.percentile(latencies, 99):.2f}" if len(latencies) else "",
            **health.values,
        }
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        out = DiagnosticArray(status=[status])
        out.header.stamp = self.get_clock().now().to_msg()
        return out


def _shape_problem(exc: MessageShapeError) -> dict[str, Any]:
    return problem_body(422, str(exc), RECOGNIZE, [{"field": "samples", "reason": str(exc)}])


def run(backend: Any, ros_args: list[str]) -> int:
    """Spin the node until SIGINT or SIGTERM; then its threads stop before rclpy does (ROS's
    own handlers would shut rclpy down under threads still publishing)."""
    import signal

    import rclpy
    import rclpy.executors
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)
    rclpy.init(args=["tactile-zsl", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = TactileBridge(backend).start()
        node.get_logger().info(f"answering from {backend.source}")
        executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok():  # short waits: a signal's handler runs between them
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.stop()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
