"""``tactile-zsl ros2``: the ROS 2 node ``tactile_zsl``, bridging topics to a service or a
model file (docs/ROS2.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ros2",
        help="run the ROS 2 node that answers samples and BioTac frames on topics",
        description="Run the ROS 2 node 'tactile_zsl': samples (~/samples) and raw BioTac "
        "frames (~/frames, with ~/procedure) in, the answers of POST /v1/recognize out "
        "(~/recognition), enrolments (~/enrol -> ~/enrolment) and /diagnostics; through a "
        "running service (--url) or a model bundle file in this process (--model). "
        "Standard ROS arguments follow --ros-args (remapping, namespace, parameters, "
        "--params-file: docs/ROS2.md); every flag below is a shorthand for a parameter and "
        "wins over it. Needs the ros2 extra or a sourced ROS 2 installation.",
    )
    source = p.add_mutually_exclusive_group()
    source.add_argument("--url", help="the service's base URL, e.g. http://fleet-server:8000")
    source.add_argument(
        "--model",
        type=Path,
        help="a model bundle file to answer with, offline (read again whenever it changes)",
    )
    p.add_argument("--api-key", help="the service's API key (with --url)")
    p.add_argument("--timeout", type=float, help="seconds per request to the service (10)")
    p.add_argument("--top-k", type=int, help="scores listed per answer with --model (default 3)")
    p.add_argument(
        "--known-kept",
        type=float,
        help="novelty operating point, a share in (0, 1) (default: the service's own)",
    )
    p.add_argument(
        "--target-confidence",
        type=float,
        help="probability at which an answer names no next procedure (default: the model's)",
    )
    p.add_argument(
        "--lifecycle",
        action="store_true",
        help="a managed (lifecycle) node: it answers once configured and activated",
    )
    p.add_argument(
        "--ros-args",
        dest="ros_args",
        nargs=argparse.REMAINDER,
        default=[],
        help="ROS's own arguments, to the end of the line: e.g. --ros-args -r "
        "__ns:=/left_hand -p queue_size:=128",
    )
    p.set_defaults(handler=run)


#: flags and the parameters they stand for
SHORTHANDS = {
    "url": "url",
    "model": "model",
    "api_key": "api_key",
    "timeout": "timeout",
    "top_k": "top_k",
    "known_kept": "known_kept",
    "target_confidence": "target_confidence",
}


def run(args: argparse.Namespace) -> int:
    from app.ros2 import require_rclpy

    if args.api_key and args.model:
        raise ValueError("--api-key goes with --url, not --model")
    if (args.timeout is not None and args.timeout <= 0) or (
        args.top_k is not None and args.top_k < 1
    ):
        raise ValueError("--timeout must be > 0 and --top-k at least 1")
    try:
        require_rclpy()
    except ImportError as exc:
        print(f"tactile-zsl ros2: error: {exc}", file=sys.stderr)
        return 2
    from app.ros2.node import check_setting
    from app.ros2.node import run as spin

    overrides = {}
    for flag, name in SHORTHANDS.items():
        value = getattr(args, flag)
        if value is not None:
            overrides[name] = str(value) if isinstance(value, Path) else value
    for name in ("known_kept", "target_confidence"):
        if name in overrides and (why := check_setting(name, overrides[name])):
            raise ValueError(why)
    ros_args = ["--ros-args", *args.ros_args] if args.ros_args else []
    return spin(ros_args, overrides, lifecycle=args.lifecycle)
