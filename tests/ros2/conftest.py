"""The bridge's tests talk DDS on this machine only: discovery kept on localhost, in a
ROS domain drawn at random for this test session, set before rclpy initialises (the
bridges started as processes inherit it)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import httpx
import pytest

from app.testing.ros2 import local_ros_environment

DOMAIN = local_ros_environment()

rclpy = pytest.importorskip("rclpy", reason="the ros2 extra is not installed")

from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl, wait_for  # noqa: E402
from app.testing.ros2 import BridgeProcess, RosClient  # noqa: E402
from app.testing.service import BEST_PARAMS, QUICK_DATASET  # noqa: E402

PILOT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "biotac_pilot"


@pytest.fixture(scope="session")
def ros() -> RosClient:
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    client = RosClient()
    yield client
    client.close()


def serve(data_dir: Path, env: dict[str, str]):
    """A real ``tactile-zsl serve`` (its embedded worker too) on a free port; its URL."""
    port = free_port()
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(data_dir),
        "TACTILE_WORKER_POLL_SECONDS": "0.1",
        "TACTILE_MODEL_POLL_SECONDS": "0.2",
        **env,
    }
    log = open(data_dir / "serve.log", "wb")  # noqa: SIM115 - closed with the process
    proc = subprocess.Popen(
        [*tactile_zsl(), "serve", "--processes", "1", "--port", str(port)],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for(lambda: httpx.get(f"{url}/readyz").status_code == 200, STARTUP_TIMEOUT, "serve")
        yield url
    finally:
        proc.terminate()
        proc.wait(60)
        log.close()


@pytest.fixture(scope="module")
def samples_service(tmp_path_factory):
    """A service on the simulated quick dataset with method best, which answers samples
    lacking procedures and names the next one."""
    yield from serve(
        tmp_path_factory.mktemp("samples-service"),
        {
            "TACTILE_DATASET": QUICK_DATASET,
            "TACTILE_METHOD": "best",
            "TACTILE_METHOD_PARAMS": json.dumps(BEST_PARAMS),
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
    for bridge in started:
        assert bridge.popen.poll() is None, f"the bridge died:\n{bridge.output()}"
        assert bridge.stop() == 0, bridge.output()
