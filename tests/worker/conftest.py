"""Shared service fixtures live in tests/service_fixtures.py; a small ``best`` service is here."""

import sys
from pathlib import Path

# The project root must be on sys.path: otherwise the folder tests/worker, as a
# namespace package, would shadow the real top-level ``worker`` package.
_ROOT = str(Path(__file__).resolve().parents[2])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

import pytest  # noqa: E402

from app.framework.registry import make_method  # noqa: E402
from tests.service_fixtures import *  # noqa: E402, F403
from tests.service_fixtures import quick_dataset, quick_settings  # noqa: E402

# ``best``'s novel part is rebuilt from the registry alone; these give a small one
BEST_PARAMS = {"seed": 0, "n_estimators": 10, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def best_base():
    dataset = quick_dataset()
    return make_method("best", **BEST_PARAMS).fit(dataset), dataset


@pytest.fixture
def best_service(tmp_path, best_base):
    """(client, app, worker) of a service whose method is ``best`` (SQLite)."""
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from worker import Worker

    app = create_app(quick_settings(tmp_path, method="best", method_params=BEST_PARAMS),
                     trainer=lambda: best_base)
    with TestClient(app) as client:
        yield client, app, Worker(app.state.settings, app.state.sessions, on_activate=app.state.holder.serve)
