"""The ROS 2 bridge: the ``tactile_zsl`` node (``tactile-zsl ros2``), which answers samples
and raw BioTac frames published on ROS 2 topics with the service's answers, through a
running service or a model file in process. docs/ROS2.md describes its topics and QoS.

rclpy comes from the ``ros2`` extra (``pip install 'tactile-zsl[ros2]'``: ROS 2 Kilted's
wheels) or from a sourced ROS 2 installation; ``require_rclpy`` says which is missing.
Only ``app.ros2.node`` and ``app.ros2.topics`` import rclpy.
"""

from __future__ import annotations


def require_rclpy() -> None:
    """ImportError naming the fix when rclpy or the message packages cannot be imported."""
    try:
        import diagnostic_msgs.msg  # noqa: F401
        import rclpy  # noqa: F401
        import std_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            f"the ROS 2 bridge needs rclpy, std_msgs and diagnostic_msgs ({exc}): "
            "pip install 'tactile-zsl[ros2]', or source a ROS 2 installation"
        ) from None
