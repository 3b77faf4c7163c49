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
        "Standard ROS arguments follow --ros-args (remapping, namespace, parameters: "
        "docs/ROS2.md). Needs the ros2 extra or a sourced ROS 2 installation.",
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--url", help="the service's base URL, e.g. http://fleet-server:8000")
    source.add_argument(
        "--model",
        type=Path,
        help="a model bundle file to answer with, offline (read again whenever it changes)",
    )
    p.add_argument("--api-key", help="the service's API key (with --url)")
    p.add_argument(
        "--timeout", type=float, default=10.0, help="seconds per request to the service (10)"
    )
    p.add_argument(
        "--top-k", type=int, default=3, help="scores listed per answer with --model (default 3)"
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


def run(args: argparse.Namespace) -> int:
    from app.ros2 import require_rclpy

    if args.api_key and args.model:
        raise ValueError("--api-key goes with --url, not --model")
    if args.timeout <= 0 or args.top_k < 1:
        raise ValueError("--timeout must be > 0 and --top-k at least 1")
    try:
        require_rclpy()
    except ImportError as exc:
        print(f"tactile-zsl ros2: error: {exc}", file=sys.stderr)
        return 2
    from app.ros2.backends import ModelFileBackend, ServiceBackend
    from app.ros2.node import run as spin

    if args.model is not None:
        from app.framework.runtime import configure_threads

        configure_threads()  # as tactile-zsl recognize: one thread unless told otherwise
        backend = ModelFileBackend(args.model, top_k=args.top_k)
    else:
        backend = ServiceBackend(args.url, api_key=args.api_key, timeout=args.timeout)
    return spin(backend, ["--ros-args", *args.ros_args] if args.ros_args else [])
