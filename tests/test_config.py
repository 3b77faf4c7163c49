"""``app.config`` stays light: reading the settings must not load the ML stack."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from app.config import Settings
from app.framework import registry
from app.framework.defaults import DEFAULT_METHOD

ROOT = Path(__file__).resolve().parents[1]


def test_importing_the_settings_loads_no_ml_library() -> None:
    # a fresh interpreter: this test process has long imported torch and scikit-learn
    code = (
        "import sys\n"
        "import app.config\n"
        "heavy = {'torch', 'sklearn', 'numpy', 'app.framework.registry'} & set(sys.modules)\n"
        "assert not heavy, sorted(heavy)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-4000:]


def test_the_default_method_is_registered_and_the_settings_default() -> None:
    assert registry.DEFAULT_METHOD == DEFAULT_METHOD
    assert DEFAULT_METHOD in registry.METHODS
    assert Settings.model_fields["method"].default == DEFAULT_METHOD
