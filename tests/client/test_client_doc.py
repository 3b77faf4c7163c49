"""docs/CLIENT.md's example runs as written against a real ``tactile-zsl serve``: only its
URL and model-file lines are pointed at the test's service and folder."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from app.testing.harness import serving
from app.testing.service import BEST_PARAMS, QUICK_DATASET

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "CLIENT.md"

pytestmark = pytest.mark.slow  # a real serve process


def example() -> tuple[str, list[str]]:
    """The Example section's Python block and its shell lines."""
    section = DOC.read_text().split("## Example", 1)[1].split("\n## ", 1)[0]
    python = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    bash = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return python, [line for line in bash.splitlines() if line.strip()]


def test_the_example_runs_against_a_real_service(tmp_path):
    python, shell = example()
    assert python.count('URL = "http://127.0.0.1:8000"') == 1
    (tmp_path / "data").mkdir()
    with serving(
        tmp_path / "data",
        {
            "TACTILE_DATASET": QUICK_DATASET,
            "TACTILE_METHOD": "best",
            "TACTILE_METHOD_PARAMS": json.dumps({"best": BEST_PARAMS}),
        },
    ) as url:
        code = python.replace('URL = "http://127.0.0.1:8000"', f'URL = "{url}"')
        run = subprocess.run(
            [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300
        )
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    assert lines[0].startswith("the 4th touch looked like ")
    source, version, name, kind = lines[1].split()
    assert source == "service" and int(version) >= 2 and kind in ("known", "novel")
    assert lines[2].startswith("refused: 409 ")
    assert lines[3].split()[0] == "offline" and lines[3].split()[1:] == [version, name]
    assert lines[4] == name  # the file in process answers as the service did
    # the shell lines: a touch saved, the model file answering it, and --lines on no input
    bin_dir = Path(sys.executable).parent
    for line in shell:
        command = line.split("   #")[0]
        command = re.sub(r"^(python|tactile-zsl)\b", lambda m: str(bin_dir / m.group(1)), command)
        done = subprocess.run(
            command,
            shell=True,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
            timeout=300,
        )
        assert done.returncode == 0, (line, done.stderr[-2000:])
        if "recognize" in command and command.rstrip().endswith("touch.npy"):
            assert json.loads(done.stdout)["results"][0]["class_name"] == name
