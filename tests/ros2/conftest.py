"""The bridge's tests talk DDS on this machine only: discovery kept on localhost, in a
ROS domain drawn at random for this test session, set before rclpy initialises (the
bridges started as processes inherit it)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from app.testing.ros2 import local_ros_environment

DOMAIN = local_ros_environment()

rclpy = pytest.importorskip("rclpy", reason="the ros2 extra is not installed")

from app.testing.ros2 import BridgeProcess, RosClient, serving  # noqa: E402
from app.testing.service import BEST_PARAMS, QUICK_DATASET  # noqa: E402

PILOT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "biotac_pilot"


@pytest.fixture(scope="session")
def ros() -> RosClient:
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    client = RosClient()
    yield client
    client.close()


def serve(data_dir: Path, env: dict[str, str]):
    """A real ``tactile-zsl serve`` (``app.testing.ros2.serving``): yields its URL."""
    with serving(data_dir, env) as url:
        yield url


@pytest.fixture(scope="module")
def samples_service(tmp_path_factory):
    """A service on the simulated quick dataset with method best, which answers samples
    lacking procedures and names the next one."""
    yield from serve(
        tmp_path_factory.mktemp("samples-service"),
        {
            "TACTILE_DATASET": QUICK_DATASET,
            "TACTILE_METHOD": "best",
            "TACTILE_METHOD_PARAMS": json.dumps({"best": BEST_PARAMS}),
        },
    )


@pytest.fixture
def bridge_factory(ros, tmp_path):
    """Start ``tactile-zsl ros2 *args`` bridges; all are stopped after the test, and each
    must have exited cleanly."""
    started: list[BridgeProcess] = []

    def start(*args: str, params=None, ready: bool = True, model: bool = True) -> BridgeProcess:
        bridge = BridgeProcess(ros, args, tmp_path / f"bridge-{len(started)}.log", params)
        started.append(bridge)
        if ready:
            bridge.wait_ready(model=model)
        return bridge

    yield start
    alive = [bridge.popen.poll() is None for bridge in started]
    codes = [bridge.stop() for bridge in started]  # every one stopped before any check
    for bridge, was_alive, code in zip(started, alive, codes, strict=True):
        assert was_alive, f"the bridge died:\n{bridge.output()}"
        assert code == 0, bridge.output()
