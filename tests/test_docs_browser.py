"""``/docs`` as an integrator first sees it: a real ``tactile-zsl serve`` and headless
Chromium, with every host but this machine unreachable, so the page must render from what
the package serves (no CDN)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl, wait_for
from app.testing.service import QUICK_DATASET, QUICK_METHOD, QUICK_PARAMS

pytestmark = pytest.mark.slow

# the screenshot is kept here for a person to look at (git ignores the folder)
SCREENSHOT_DIR = Path(__file__).resolve().parents[1] / "results" / "docs-page"


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is not installed: .ci/run installs Debian's chromium")
        pytest.skip("Debian's chromium is not installed (apt-get install chromium)")
    return found


@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Iterator[str]:
    data_dir = tmp_path_factory.mktemp("docs-service")
    port = free_port()
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(data_dir),
        "TACTILE_DATASET": QUICK_DATASET,
        "TACTILE_METHOD": QUICK_METHOD,
        "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
    }
    log = data_dir / "serve.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [*tactile_zsl(), "serve", "--processes", "1", "--no-worker", "--port", str(port)],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for(lambda: httpx.get(f"{url}/readyz").status_code == 200, STARTUP_TIMEOUT, "serve")
        assert f"API docs at {url}/docs" in log.read_text()  # the log says where the page is
        yield url
    finally:
        proc.terminate()
        proc.wait(30)


def render(url: str, screenshot: Path | None = None) -> str:
    """The page's DOM after its scripts ran; other hosts resolve to nothing."""
    args = [
        chromium(),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        "--virtual-time-budget=15000",
        "--window-size=1280,2400",
    ]
    if screenshot is not None:
        screenshot.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            [*args, f"--screenshot={screenshot}", url], capture_output=True, timeout=120, check=True
        )
    run = subprocess.run([*args, "--dump-dom", url], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout


def test_docs_lists_every_operation_without_a_render_error(service):
    spec = httpx.get(f"{service}/openapi.json").json()
    dom = render(f"{service}/docs", SCREENSHOT_DIR / "docs.png")
    assert "Unable to render" not in dom and "valid version field" not in dom
    rendered = set(re.findall(r'id="operations-(?!tag-)([\w-]+)"', dom))  # not the tag headings
    expected = {
        f"{op['tags'][0]}-{op['operationId']}"
        for ops in spec["paths"].values()
        for op in ops.values()
    }
    assert len(expected) > 20 and rendered == expected
    assert "Tactile recognition service" in dom
    assert (SCREENSHOT_DIR / "docs.png").stat().st_size > 20_000  # a drawn page, not a blank one


def test_docs_page_loads_nothing_from_outside(service):
    html = httpx.get(f"{service}/docs").text
    sources = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert sources and all(s.startswith("/") for s in sources), sources
    for source in sources:
        assert httpx.get(f"{service}{source}").status_code == 200, source
