"""The ``tactile_zsl`` node: samples and raw BioTac frames in, the service's answers out.

Subscription callbacks only read and queue (``AnswerQueue``); one worker thread answers the
queue in order through the backend and publishes each answer; a second thread runs
enrolments in the order they came (they wait for the retrained model, minutes maybe), a
third probes the backend and publishes ``/diagnostics``. No input, fault or answer raises
out of a callback or a thread: what cannot be answered is answered with a problem. Every
answer names its input (``input``: the message's publication sequence number, source
stamp, and the sample's index in a message that held several).

``TactileBridge`` configures itself and answers at once; ``LifecycleBridge``
(``--lifecycle``) is a managed node: ``configure`` reaches the backend and reads its
model, ``activate`` starts answering, ``deactivate`` stops answering and keeps the inputs
that came meanwhile for ``activate``.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import orjson
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from std_msgs.msg import Float32MultiArray, String

from app.api.problems import problem_body
from app.data.biotac_phases import PhaseRule
from app.data.contacts import ContactMarks
from app.ros2 import topics
from app.ros2.arrays import MessageShapeError, frame_of, samples_of, stamped_of
from app.ros2.backends import CLASSES, RECOGNIZE, Health, backend_of, internal_problem
from app.ros2.queue import AnswerQueue, InputRef, SequenceGaps, Work
from app.ros2.trials import MarkOrder, TrialAssembler, TrialProblem

NODE_NAME = "tactile_zsl"
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Param:
    """A ROS parameter of the node: its default, what it means, whether it may change
    while the node runs (``ros2 param set``), and its range."""

    default: Any
    description: str
    dynamic: bool = False
    low: float | None = None
    high: float | None = None

    def descriptor(self, name: str) -> ParameterDescriptor:
        d = ParameterDescriptor(name=name, description=self.description, read_only=not self.dynamic)
        if self.low is not None and isinstance(self.default, float):
            d.floating_point_range = [
                FloatingPointRange(from_value=self.low, to_value=self.high, step=0.0)
            ]
        elif self.low is not None:
            d.integer_range = [
                IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)
            ]
        return d


#: ROS parameters (``--ros-args -p name:=value`` or ``--params-file``); docs/ROS2.md lists them
PARAMETERS: dict[str, Param] = {
    "url": Param("", "the service's base URL (this or model)"),
    "api_key": Param("", "the service's API key (with url)"),
    "model": Param("", "a model bundle file to answer with in process (this or url)"),
    "timeout": Param(10.0, "seconds per request to the service", low=0.001, high=3600.0),
    "top_k": Param(3, "scores listed per answer with model", low=1, high=1000),
    "known_kept": Param(
        0.0,
        "novelty operating point: share of known touches kept, in (0, 1); 0: the "
        "service's (or model file's) own",
        dynamic=True,
        low=0.0,
        high=1.0,
    ),
    "target_confidence": Param(
        0.0,
        "probability at which a sample's answer names no next procedure, in (0, 1]; "
        "0: the model's own",
        dynamic=True,
        low=0.0,
        high=1.0,
    ),
    "queue_size": Param(
        64, "inputs waiting for an answer; beyond, each gets a 503", low=1, high=1_000_000
    ),
    "input_depth": Param(100, "keep-last depth of ~/samples", low=1, high=1_000_000),
    "frame_depth": Param(10_000, "keep-last depth of ~/frames", low=1, high=1_000_000),
    "answer_depth": Param(1000, "keep-last depth of the answer topics", low=1, high=1_000_000),
    "diagnostics_period": Param(
        1.0, "seconds between /diagnostics messages", low=0.01, high=3600.0
    ),
    "rest_frames": Param(
        100, "frames before a trial's first mark kept as its rest", low=1, high=1_000_000
    ),
    "max_trial_frames": Param(
        60_000, "a longer trial is answered with a problem", low=2, high=100_000_000
    ),
    "enrol_queue_size": Param(
        16, "enrolments waiting; beyond, each gets a 503", low=1, high=100_000
    ),
    "mark_wait": Param(1.0, "seconds a mark waits for a frame to place it", low=0.0, high=3600.0),
    "contact_detection": Param(
        False, "cut trials from finger 0's pdc by contact, not by ~/procedure marks"
    ),
}
LATENCIES_KEPT = 1000


def check_setting(name: str, value: Any) -> str | None:
    """Why ``value`` cannot be parameter ``name`` (the ranges ROS does not check), or None."""
    if name == "known_kept" and not (value == 0.0 or 0.0 < value < 1.0):
        return f"known_kept must lie in (0, 1), or be 0 for the service's own; got {value}"
    if name == "target_confidence" and not (0.0 <= value <= 1.0):
        return f"target_confidence must lie in (0, 1], or be 0 for the model's own; got {value}"
    return None


class BridgeCore:
    """The bridge's work, shared by ``TactileBridge`` and ``LifecycleBridge`` (both
    ``rclpy`` nodes): ``_declare`` in the constructor, then ``_configure``,
    ``_activate``, ``_deactivate``, ``_teardown``."""

    backend: Any

    def _declare(self, backend: Any | None) -> None:
        for name, param in PARAMETERS.items():
            self.declare_parameter(name, param.default, param.descriptor(name))
        self.settings = {name: self.get_parameter(name).value for name in PARAMETERS}
        for name in ("known_kept", "target_confidence"):
            if why := check_setting(name, self.settings[name]):
                raise ValueError(why)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.backend = backend
        self._active = threading.Event()
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._entities: list[Any] = []
        self._configured = False

    # ----------------------------------------------------------------- lifecycle
    def _configure(self) -> None:
        """Build the backend (from the parameters unless given), queues, topics, threads."""
        p = self.settings
        if self.backend is None:
            self.backend = backend_of(p)
        self.answers = AnswerQueue(int(p["queue_size"]))
        self.enrolments = AnswerQueue(int(p["enrol_queue_size"]))
        self.assembler = TrialAssembler(int(p["rest_frames"]), int(p["max_trial_frames"]))
        self.marks = MarkOrder(float(p["mark_wait"]))
        self.contacts: ContactMarks | None = None  # made for the model's procedures
        self.sample_gaps, self.frame_gaps = SequenceGaps(), SequenceGaps()
        self.diagnostics_period = float(p["diagnostics_period"])
        self._latencies: deque[float] = deque(maxlen=LATENCIES_KEPT)
        self._counts = {"answered": 0, "frames": 0, "bad_frames": 0}
        self._rate_mark = (time.monotonic(), 0)  # (when, answered) at the last diagnostics
        self._health = Health(False, "not probed yet")
        self._stopping.clear()

        answer_qos = topics.reliable_qos(int(p["answer_depth"]))
        self.recognition = self.create_publisher(String, topics.RECOGNITION, answer_qos)
        self.enrolment = self.create_publisher(String, topics.ENROLMENT, answer_qos)
        self.diagnostics = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self._subscriptions_made = [
            self.create_subscription(
                Float32MultiArray,
                topics.SAMPLES,
                self._on_samples,
                topics.sensor_qos(int(p["input_depth"])),
            ),
            self.create_subscription(
                String,
                topics.SAMPLES_STAMPED,
                self._on_stamped,
                topics.sensor_qos(int(p["input_depth"])),
            ),
            self.create_subscription(
                Float32MultiArray,
                topics.FRAMES,
                self._on_frame,
                topics.sensor_qos(int(p["frame_depth"])),
            ),
            self.create_subscription(
                String, topics.PROCEDURE, self._on_procedure, topics.reliable_qos(100)
            ),
            self.create_subscription(
                String, topics.ENROL, self._on_enrol, topics.reliable_qos(100)
            ),
        ]
        self._timer = self.create_timer(0.1, self._flush_marks)
        for target in (self._answer_loop, self._enrol_loop, self._health_loop):
            thread = threading.Thread(target=target, name=f"{NODE_NAME}{target.__name__}")
            thread.daemon = True  # a backend call stuck past stop() must not hold the exit
            thread.start()
            self._threads.append(thread)
        self._configured = True

    def _teardown(self, timeout: float = 5.0) -> None:
        """Stop the threads, destroy the topics, close the backend (configure builds anew)."""
        if not self._configured:
            return
        self._active.clear()
        self._stopping.set()
        for thread in self._threads:
            thread.join(timeout)
        self._threads.clear()
        for sub in self._subscriptions_made:
            self.destroy_subscription(sub)
        for pub in (self.recognition, self.enrolment, self.diagnostics):
            self.destroy_publisher(pub)
        self.destroy_timer(self._timer)
        self.backend.close()
        self.backend = None
        self._configured = False

    def stop(self, timeout: float = 5.0) -> None:
        self._teardown(timeout)

    @property
    def active(self) -> bool:
        return self._active.is_set()

    # ---------------------------------------------------------------- parameters
    def _on_set_parameters(self, params: list[Any]) -> SetParametersResult:
        for param in params:
            if param.name in PARAMETERS and PARAMETERS[param.name].dynamic:
                if why := check_setting(param.name, float(param.value)):
                    return SetParametersResult(successful=False, reason=why)
        for param in params:
            if param.name in PARAMETERS:
                self.settings[param.name] = param.value
        return SetParametersResult(successful=True)

    def _setting(self, name: str) -> float | None:
        """A dynamic setting as the backend takes it: None for 0 (the backend's own)."""
        value = float(self.settings[name])
        return value or None

    # ---------------------------------------------------------------- callbacks
    def _on_samples(self, msg: Float32MultiArray, info: Any) -> None:
        received = time.perf_counter()
        ref = InputRef.of(info)
        self.sample_gaps.seen(info)
        try:
            model = self.backend.model
            shape = model.input_shape if model else None
            x = samples_of(msg, shape)
            several = bool(shape) and x.ndim == len(shape) + 1
            work = Work("samples", (x, several), received, [ref])
        except MessageShapeError as exc:
            work = Work("problem", _shape_problem(exc), received, [ref])
        except Exception:  # noqa: BLE001 - the input still gets its answer
            log.exception("reading a samples message")
            work = Work("problem", internal_problem(RECOGNIZE), received, [ref])
        self.answers.put(work)

    def _on_stamped(self, msg: String, info: Any) -> None:
        """Samples as JSON with the robot's ``std_msgs/Header``, echoed in the answer."""
        received = time.perf_counter()
        ref = InputRef.of(info)
        self.sample_gaps.seen(info)
        try:
            x, header, objects = stamped_of(msg.data)
            ref = InputRef(ref.sequence, ref.stamp, None, header)
            model = self.backend.model
            shape = model.input_shape if model else None
            several = bool(shape) and x.ndim == len(shape) + 1
            if objects is None:
                work = Work("samples", (x, several), received, [ref])
            else:  # a table: one answer, one result per object
                work = Work("table", (x, objects), received, [ref])
        except MessageShapeError as exc:
            field = str(exc).split(":", 1)[0].split(".", 1)[0]
            problem = problem_body(422, str(exc), RECOGNIZE, [{"field": field, "reason": str(exc)}])
            work = Work("problem", problem, received, [ref])
        except Exception:  # noqa: BLE001 - the input still gets its answer
            log.exception("reading a stamped samples message")
            work = Work("problem", internal_problem(RECOGNIZE), received, [ref])
        self.answers.put(work)

    def _on_frame(self, msg: Float32MultiArray, info: dict[str, Any]) -> None:
        self._counts["frames"] += 1
        try:
            lost = self.frame_gaps.seen(info)
            frame = frame_of(msg)
            for mark in self.marks.frame(info["source_timestamp"], time.monotonic()):
                self._follow(mark, 0, time.perf_counter())
            if lost:
                self.assembler.lost(lost)
            if self.settings["contact_detection"]:
                for text, late in self._contact_marks(frame):
                    self._follow((text, InputRef.of(info)), late, time.perf_counter())
            self.assembler.frame(frame)
        except MessageShapeError as exc:
            self._counts["bad_frames"] += 1
            self.assembler.fault(f"frame message {self._counts['frames']}: {exc}")
        except Exception:  # noqa: BLE001
            log.exception("reading a frame message")
            self.assembler.fault("a frame could not be read (the bridge's log has the details)")

    def _contact_marks(self, frame: np.ndarray) -> list[tuple[str, int]]:
        """The marks contact detection finds before ``frame`` (``app.data.contacts``, as
        ``tactile-zsl dataset bag`` cuts a bag of frames alone); none before the model is
        known, whose procedures the contacts are."""
        model = self.backend.model
        if model is None or not model.procedures:
            return []
        if self.contacts is None or self.contacts.procedures != tuple(model.procedures):
            rule = PhaseRule(len(model.procedures), int(self.settings["rest_frames"]))
            self.contacts = ContactMarks(model.procedures, rule)
        return self.contacts.frame(frame)

    def _on_procedure(self, msg: String, info: dict[str, Any]) -> None:
        received = time.perf_counter()
        if self.settings["contact_detection"]:
            detail = (
                f"procedure mark {msg.data!r} not followed: the bridge cuts trials by contact "
                "(contact_detection:=true)"
            )
            errors = [{"field": "procedure", "reason": detail}]
            problem = problem_body(422, detail, RECOGNIZE, errors)
            self.answers.put(Work("problem", problem, received, [InputRef.of(info)]))
            return
        mark = (msg.data, InputRef.of(info))
        for due, late in self.marks.mark(mark, info["source_timestamp"]):
            self._follow(due, late, received)

    def _flush_marks(self) -> None:
        for mark in self.marks.flush(time.monotonic()):
            self._follow(mark, 0, time.perf_counter())

    def _follow(self, mark: tuple[str, InputRef], late: int, received: float) -> None:
        """Follow a procedure mark ``late`` frames back; queue the answer it calls for,
        named by the mark that completed the procedure."""
        name, ref = mark
        try:
            model = self.backend.model
            if model is None:
                detail = f"the model of {self.backend.source} is not known yet (not reached)"
                work = Work("problem", problem_body(503, detail, RECOGNIZE), received, [ref])
            else:
                trial = self.assembler.procedure(name, model.procedures, late)
                if trial is None:
                    return  # a trial's first procedure: nothing to answer yet
                ref = InputRef(
                    ref.sequence, ref.stamp, None, ref.header, self.assembler.completed_missing
                )
                work = Work("trial", trial, received, [ref])
        except TrialProblem as exc:
            missing = (
                self.assembler.completed_missing
                if "frames" in str(exc.problem.get("errors"))
                else None
            )
            ref = InputRef(ref.sequence, ref.stamp, None, ref.header, missing)
            work = Work("problem", exc.problem, received, [ref])
        except Exception:  # noqa: BLE001
            log.exception("following a procedure message")
            work = Work("problem", internal_problem(RECOGNIZE), received, [ref])
        self.answers.put(work)

    def _on_enrol(self, msg: String, info: Any) -> None:
        received, ref = time.perf_counter(), InputRef.of(info)
        try:
            body = json.loads(msg.data)
            if not isinstance(body, dict):
                raise ValueError("the message must hold a JSON object, POST /v1/classes's body")
            work = Work("enrol", body, received, [ref])
        except ValueError as exc:
            detail = f"body: malformed JSON: {exc}"
            problem = problem_body(422, detail, CLASSES, [{"field": "body", "reason": detail}])
            work = Work("problem", problem, received, [ref])
        # the problem waits its turn too: an answer never overtakes an earlier enrolment's
        self.enrolments.put(work)

    # -------------------------------------------------------------------- loops
    def _answer_loop(self) -> None:
        while not self._stopping.is_set():
            if not self._active.wait(0.2):
                continue  # inactive: inputs wait in the queue for activation
            work = self.answers.get(timeout=0.2)
            if work is None:
                continue
            if not self._active.is_set():  # deactivated while it waited: keep it
                self.answers.unget(work)
                continue
            try:
                answers = self._answer(work)
            except Exception:  # noqa: BLE001 - the slot is answered whatever happens
                log.exception("answering %s", work.kind)
                answers = [(internal_problem(RECOGNIZE), ref) for ref in work.inputs]
            for body, ref in answers:
                self._publish(self.recognition, body, ref)
                self._latencies.append(time.perf_counter() - work.received)
                self._counts["answered"] += 1

    def _answer(self, work: Work) -> list[tuple[dict[str, Any], InputRef]]:
        """Each answer ``work`` calls for, with the input it names."""
        (ref, *_) = work.inputs
        if work.kind == "samples":
            x, several = work.payload
            body = self.backend.recognize(
                x, self._setting("target_confidence"), self._setting("known_kept")
            )
            results = body.get("results")
            if several and isinstance(results, list) and len(results) == len(x):
                return [({**body, "results": [r]}, ref.at(k)) for k, r in enumerate(results)]
            return [(body, ref)]
        if work.kind == "table":
            x, objects = work.payload
            table = self.backend.recognize(
                x, self._setting("target_confidence"), self._setting("known_kept"), objects
            )
            return [(table, ref)]
        if work.kind == "trial":
            return [(self.backend.recognize_trial(work.payload, self._setting("known_kept")), ref)]
        if work.kind == "refused":
            detail = (
                f"the bridge's queue of {self.answers.capacity} inputs was full (answers come "
                "slower than inputs): this input was not recognised"
            )
            problem = problem_body(503, detail, RECOGNIZE)
            return [(problem, r) for r in work.inputs]
        return [(work.payload, ref)]

    def _enrol_loop(self) -> None:
        while not self._stopping.is_set():
            if not self._active.wait(0.2):
                continue
            work = self.enrolments.get(timeout=0.2)
            if work is None:
                continue
            if not self._active.is_set():
                self.enrolments.unget(work)
                continue
            for ref in work.inputs:
                try:
                    if work.kind == "enrol":
                        outcome = self.backend.enrol(work.payload)
                    elif work.kind == "refused":
                        detail = (
                            f"the bridge's {self.enrolments.capacity} enrolments waiting "
                            "filled its queue; this one was not sent: publish it again later"
                        )
                        outcome = problem_body(503, detail, CLASSES)
                    else:
                        outcome = work.payload
                except Exception:  # noqa: BLE001
                    log.exception("enrolling")
                    outcome = internal_problem(CLASSES)
                self._publish(self.enrolment, outcome, ref)

    def _health_loop(self) -> None:
        while not self._stopping.is_set():
            try:
                self._health = self.backend.probe()
                self.diagnostics.publish(self.diagnostic_array())
            except Exception:  # noqa: BLE001
                log.exception("probing the backend")
            self._stopping.wait(self.diagnostics_period)

    # ------------------------------------------------------------------ helpers
    def _publish(self, publisher: Any, body: dict[str, Any], ref: InputRef) -> None:
        publisher.publish(String(data=orjson.dumps({**body, "input": ref.json()}).decode()))

    def diagnostic_array(self) -> DiagnosticArray:
        """The bridge's state, as diagnostic_updater publishes a task's: whether the
        backend answers, its model, the queue, inputs lost, answer rate and latency."""
        health = self._health
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: recognition")
        status.hardware_id = str(self.backend.source)
        waiting = len(self.answers)
        if not health.reachable:
            status.level, status.message = DiagnosticStatus.ERROR, health.message
        elif health.warning or waiting >= self.answers.capacity:
            status.level = DiagnosticStatus.WARN
            status.message = health.warning or "the answer queue is full"
        elif not self.active:
            status.level, status.message = DiagnosticStatus.OK, "inactive: inputs wait"
        else:
            status.level, status.message = DiagnosticStatus.OK, health.message
        latencies = np.array(self._latencies) * 1e3
        now, answered = time.monotonic(), self._counts["answered"]
        then, before = self._rate_mark
        self._rate_mark = (now, answered)
        rate = (answered - before) / (now - then) if now > then else 0.0
        model = health.model
        values = {
            "reachable": str(health.reachable).lower(),
            "active": str(self.active).lower(),
            "model_version": str(model.version) if model else "",
            "input_kind": model.input_kind if model else "",
            "procedures": ",".join(model.procedures) if model else "",
            "queue": f"{waiting}/{self.answers.capacity}",
            "answered": str(answered),
            "answer_rate_hz": f"{rate:.2f}",
            "refused_queue_full": str(self.answers.refused),
            "enrolments_refused_queue_full": str(self.enrolments.refused),
            "samples_missing": str(self.sample_gaps.missing),
            "frames": str(self._counts["frames"]),
            "frames_missing": str(self.frame_gaps.missing),
            "bad_frames": str(self._counts["bad_frames"]),
            "known_kept": str(self.settings["known_kept"]),
            "target_confidence": str(self.settings["target_confidence"]),
            "latency_p50_ms": f"{np.percentile(latencies, 50):.2f}" if len(latencies) else "",
            "latency_p99_ms": f"{np.percentile(latencies, 99):.2f}" if len(latencies) else "",
            **health.values,
        }
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        out = DiagnosticArray(status=[status])
        out.header.stamp = self.get_clock().now().to_msg()
        return out


class TactileBridge(BridgeCore, Node):
    """The node, answering at once through ``backend`` (``app.ros2.backends``; None: the
    one its parameters name). ``stop`` its threads before destroying it."""

    def __init__(self, backend: Any | None = None, **node_options: Any) -> None:
        Node.__init__(self, NODE_NAME, **node_options)
        self._declare(backend)
        self._configure()
        self._active.set()

    def start(self) -> TactileBridge:
        return self  # configured and active from the start


class LifecycleBridge(BridgeCore, LifecycleNode):
    """The managed node: unconfigured until ``configure``, which reaches the backend and
    reads its model (it fails where it cannot); answering only while active."""

    def __init__(self, backend: Any | None = None, **node_options: Any) -> None:
        LifecycleNode.__init__(self, NODE_NAME, **node_options)
        self._declare(backend)

    def on_configure(self, state: Any) -> TransitionCallbackReturn:
        try:
            self._configure()
            health = self.backend.probe()
        except Exception as exc:  # noqa: BLE001 - a failed transition, said in the log
            self.get_logger().error(f"configure: {exc}")
            self._teardown()
            return TransitionCallbackReturn.FAILURE
        if not health.reachable or health.model is None:
            self.get_logger().error(f"configure: {self.backend.source}: {health.message}")
            self._teardown()
            return TransitionCallbackReturn.FAILURE
        self._health = health
        self.get_logger().info(
            f"configured: {self.backend.source}, model version {health.model.version}"
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: Any) -> TransitionCallbackReturn:
        self._active.set()
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: Any) -> TransitionCallbackReturn:
        self._active.clear()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: Any) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: Any) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS


def _shape_problem(exc: MessageShapeError) -> dict[str, Any]:
    return problem_body(422, str(exc), RECOGNIZE, [{"field": "samples", "reason": str(exc)}])


def run(
    ros_args: list[str],
    overrides: dict[str, Any] | None = None,
    lifecycle: bool = False,
    backend: Any | None = None,
) -> int:
    """Spin the node until SIGINT or SIGTERM; then its threads stop before rclpy does (ROS's
    own handlers would shut rclpy down under threads still publishing). ``overrides``:
    parameters given as command-line flags, over those of ``ros_args``."""
    import signal

    import rclpy
    import rclpy.executors
    from rclpy.executors import ExternalShutdownException
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)
    rclpy.init(args=["tactile-zsl", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    params = [Parameter(k, value=v) for k, v in (overrides or {}).items()]
    try:
        kind = LifecycleBridge if lifecycle else TactileBridge
        node = kind(backend, parameter_overrides=params)
        if not lifecycle:
            node.get_logger().info(f"answering from {node.backend.source}")
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
