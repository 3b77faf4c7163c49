"""``TACTILE_METHOD_PARAMS`` names each method, and what a service would fail on at its
first refit fails when the settings are read, naming the fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from pydantic import ValidationError

from app.config import Settings


def test_each_method_gets_its_own_and_auto_passes_its_candidates_theirs():
    params = {"best": {"n_estimators": 50}, "auto": {"probe_classes": 20}}
    settings = Settings(method="auto", method_params=json.dumps(params))
    assert settings.params_for() == {"probe_classes": 20, "params": {"best": {"n_estimators": 50}}}
    assert settings.params_for("best") == {"n_estimators": 50}
    assert settings.params_for("prototypes") == {}
    fixed = Settings(method="best", method_params={"best": {"n_estimators": 50}})
    assert fixed.params_for() == {"n_estimators": 50}


@pytest.mark.parametrize(
    ("method", "params", "named"),
    [
        ("auto", {"n_estimators": 50}, '{"best": {"n_estimators": ...}}'),
        ("auto", {"best": {"n_estimatorz": 5}}, "best does not take"),
        ("auto", {"best": {"n_estimators": -1}}, "n_estimators must be"),
        ("auto", {"paper": {}}, "never fits"),
        ("prototypes", {"best": {"n_estimators": 5}}, "never fits"),
        ("auto", {"auto": {"params": {}}}, "under its own name"),
        ("auto", {"best": 5}, "must be a JSON object"),
        ("auto", [1], "must be a JSON object"),
    ],
)
def test_bad_parameters_are_refused_when_the_settings_are_read(method, params, named):
    with pytest.raises(ValidationError, match="TACTILE_METHOD_PARAMS") as raised:
        Settings(method=method, method_params=json.dumps(params))
    assert named in str(raised.value)


def test_serve_stops_at_start_with_exit_2_and_the_fix(tmp_path):
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(tmp_path),
        "TACTILE_METHOD_PARAMS": json.dumps({"n_estimators": 50}),
    }
    done = subprocess.run(
        [sys.executable, "-m", "app.cli", "serve", "--port", "0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert 'under their method\'s name; write {"best": {"n_estimators": ...}}' in done.stderr
