"""The bridge's topics and their QoS (docs/ROS2.md lists them for users).

Inputs a sensor streams (samples, raw frames) take the sensor-data QoS: best effort,
volatile, keep last ``depth``, so that a publisher of either reliability is heard and a
slow link drops frames rather than stalls the sensor. Commands (procedure marks,
enrolments) and every answer are reliable, volatile, keep last ``depth``: an answer or a
trial boundary is never dropped on the wire.
"""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

SAMPLES = "~/samples"  # std_msgs/Float32MultiArray in
SAMPLES_STAMPED = "~/samples_stamped"  # std_msgs/String in: {"header", "samples"} as JSON
FRAMES = "~/frames"  # std_msgs/Float32MultiArray in: raw BioTac frames
PROCEDURE = "~/procedure"  # std_msgs/String in: a procedure's name, or "end"
RECOGNITION = "~/recognition"  # std_msgs/String out: POST /v1/recognize's JSON body
ENROL = "~/enrol"  # std_msgs/String in: POST /v1/classes's JSON body
ENROLMENT = "~/enrolment"  # std_msgs/String out: the finished job, or a problem
DIAGNOSTICS = "/diagnostics"  # diagnostic_msgs/DiagnosticArray out


def sensor_qos(depth: int) -> QoSProfile:
    """Sensor-data QoS (best effort, volatile) keeping the last ``depth`` messages."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=qos_profile_sensor_data.reliability,
        durability=qos_profile_sensor_data.durability,
    )


def reliable_qos(depth: int) -> QoSProfile:
    """Reliable, volatile, keep last ``depth``."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
