"""Fixtures shared by tests/api, tests/store, tests/worker and the end-to-end test.

One small model is trained once per test process (``trained_base``) and every
test's fresh store is bootstrapped from it, so no test waits for training
except the few that retrain on purpose.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import io
import itertools
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.data.dataset import TactileDataset
from app.framework.recognizer import TactileRecognizer
from app.framework.registry import make_method

# Small and short: seconds on 2 CPU cores. Accuracy is not what these tests check.
# The service tests pin the paper's pipeline: its epochs can be cut to seconds, and the
# service only uses the TactileRecognizer interface, which tests/methods checks for `best`.
QUICK_METHOD = "paper"
QUICK_PARAMS: dict = {
    "seed": 0,
    "encoder_epochs": 3,
    "alg1_epochs": 5,
    "alg2_epochs": 2,
    "fc_z_epochs": 5,
    "finetune_steps": 3,
    "mlp_hidden": 32,
    "mlp_features": 16,
    "gmm_components": 2,
    "novelty_pca_dims": 4,
}
QUICK_OBJECTS = 10
QUICK_TRIALS = 6
QUICK_DATASET = f"simulated:{QUICK_OBJECTS}"


def quick_dataset() -> TactileDataset:
    from app.data.simulator import simulate_dataset

    return simulate_dataset(n_objects=QUICK_OBJECTS, trials_per_object=QUICK_TRIALS, seed=0)


@functools.cache
def _train_once() -> tuple[TactileRecognizer, TactileDataset]:
    dataset = quick_dataset()
    return make_method(QUICK_METHOD, **QUICK_PARAMS).fit(dataset), dataset


def trained_base() -> tuple[TactileRecognizer, TactileDataset]:
    """The one quick model of this test process (the store only serialises it)."""
    return _train_once()


def unused_vectors(dataset: TactileDataset, n: int) -> list[list[int]]:
    """``n`` attribute vectors no dataset class has, each with two attributes set."""
    taken = {tuple(int(v) for v in row) for row in dataset.class_attributes}
    out = []
    for i, j in itertools.combinations(range(dataset.n_attributes), 2):
        v = [0] * dataset.n_attributes
        v[i] = v[j] = 1
        if tuple(v) not in taken:
            out.append(v)
        if len(out) == n:
            return out
    raise AssertionError("no unused attribute vectors left")


def names_of(vector: list[int], dataset: TactileDataset) -> list[str]:
    return [a for a, bit in zip(dataset.attribute_names, vector, strict=True) if bit]


PROBLEM = "application/problem+json"


def problem(response, status: int, field: str | None = None) -> dict:
    """The RFC 9457 body of an error ``response``, checked: its status, content type, and
    the field it names (when ``field`` is given)."""
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    body = response.json()
    assert body["status"] == status and body["title"] and body["detail"]
    if field:
        assert field in [e["field"] for e in body["errors"]], body
    return body


def register(client, dataset: TactileDataset, name: str, i: int = 0) -> dict:
    """POST /v1/classes of ``name`` with the ``i``-th unused attribute vector; the 202 body."""
    vector = unused_vectors(dataset, i + 1)[i]
    r = client.post("/v1/classes", json={"name": name, "attributes": names_of(vector, dataset)})
    assert r.status_code == 202, r.text
    return r.json()


def add_sample(client, class_id: int, sample) -> dict:
    """POST /v1/classes/{class_id}/samples; the 202 body."""
    r = client.post(f"/v1/classes/{class_id}/samples", json={"sample": np.asarray(sample).tolist()})
    assert r.status_code == 202, r.text
    return r.json()


def job(client, job_id: int) -> dict:
    return client.get(f"/v1/jobs/{job_id}").json()


def npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()


def error_contract_breach(label: str, response) -> str | None:
    """What a (fuzzed) response does wrong, if anything: every 5xx is a bug, and every 4xx
    must be application/problem+json. Shared by the fuzz test and bench/fuzz.py."""
    content_type = response.headers.get("content-type", [""])[0]
    if response.status_code >= 500:
        return f"{label}: {response.status_code} {response.text[:200]}"
    if response.status_code >= 400 and content_type != "application/problem+json":
        return f"{label}: {response.status_code} as {content_type}"
    return None


def quick_settings(data_dir, **overrides) -> Settings:
    values = {
        "data_dir": data_dir,
        "embedded_worker": False,
        "dataset": QUICK_DATASET,
        "method": QUICK_METHOD,
        "method_params": QUICK_PARAMS,
        "model_poll_seconds": 0.05,
        "worker_poll_seconds": 0.05,
        "lease_seconds": 10.0,
        "promotion_threshold": 10,
    }
    return Settings(**{**values, **overrides})


def store_check(settings: Settings) -> tuple[int, str]:
    """``tactile-zsl store check`` on the settings' store in a process of its own, as an
    operator runs it: (exit code, output)."""
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(settings.data_dir),
        "TACTILE_DATABASE_URL": settings.database_url or "",
    }
    out = subprocess.run(
        [sys.executable, "-m", "app.cli", "store", "check"],
        env=env,
        cwd=Path(__file__).resolve().parents[1],
        capture_output=True,
        text=True,
        timeout=300,
    )
    return out.returncode, out.stdout + out.stderr


def list_all(client, path: str, key: str) -> list[dict]:
    """Every row of a paged list endpoint (``/v1/classes``, ``/v1/models``), following
    ``next_after``; ``client`` is an httpx client or a TestClient."""
    rows, params = [], {"limit": 1000}
    while True:
        r = client.get(path, params=params)
        assert r.status_code == 200, r.text
        rows += r.json()[key]
        if r.json()["next_after"] is None:
            return rows
        params = {"limit": 1000, "after": r.json()["next_after"]}


def wait_for_job(client: TestClient, job_id: int, timeout: float = 60) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        wait = min(20.0, max(0.0, deadline - time.monotonic()))
        job = client.get(f"/v1/jobs/{job_id}", params={"wait": round(wait, 3)}).json()
        if job["status"] in ("succeeded", "failed") or time.monotonic() > deadline:
            return job


# -------------------------------------------------------------------- fixtures


@pytest.fixture(scope="session")
def base_model() -> tuple[TactileRecognizer, TactileDataset]:
    return trained_base()


@contextlib.contextmanager
def fresh_postgres_database(admin_url: str) -> Iterator[str]:
    """A new empty database on the server of ``admin_url``, dropped afterwards."""
    from sqlalchemy import text
    from sqlalchemy.engine import make_url

    from app.store.db import make_engine

    name = f"tactile_test_{uuid.uuid4().hex[:12]}"
    admin = make_engine(admin_url).execution_options(isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield make_url(admin_url).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.engine.dispose()


DEFAULT_POSTGRES_URL = "postgresql://postgres@127.0.0.1:5432/test"


@functools.cache
def postgres_url() -> str | None:
    """The admin URL of a reachable PostgreSQL server for the tests, or None.

    TACTILE_TEST_POSTGRES_URL, else the machine's local server; tests that need one
    are skipped (with this reason shown) when it cannot be reached.
    """
    from sqlalchemy import text

    from app.store.db import make_engine

    url = os.environ.get("TACTILE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL)
    engine = make_engine(url, timeout=3)
    try:
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        return url
    except Exception:  # noqa: BLE001 - any failure means "no server for the tests"
        return None
    finally:
        engine.dispose()


def require_postgres() -> str:
    url = postgres_url()
    if url is None:
        pytest.skip(
            "PostgreSQL not reachable at "
            + os.environ.get("TACTILE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL)
        )
    return url


@pytest.fixture(params=["sqlite", "postgresql"])
def settings(request, tmp_path) -> Iterator[Settings]:
    """Every service test runs on both stores: SQLite under tmp_path, and a fresh
    PostgreSQL database (skipped, with the reason, when no server is reachable)."""
    if request.param == "sqlite":
        yield quick_settings(tmp_path / "data")
        return
    with fresh_postgres_database(require_postgres()) as db_url:
        yield quick_settings(tmp_path / "data", database_url=db_url)


@pytest.fixture
def app(settings, base_model):
    from app.api.main import create_app

    return create_app(settings, trainer=lambda: base_model)


@pytest.fixture
def client(app) -> Iterator[TestClient]:
    with TestClient(app) as c:  # runs the lifespan: migrate, bootstrap, load the model
        yield c


@pytest.fixture
def worker(app, client):
    """A worker on the app's store, run by hand with ``worker.run_once()``."""
    from worker import Worker

    holder = app.state.service.holder
    return Worker(app.state.service.settings, app.state.service.sessions, on_activate=holder.serve)


@pytest.fixture
def store(settings, base_model):
    """(engine, sessions) of a migrated store holding the bootstrapped base model."""
    from app.service.bootstrap import ensure_ready
    from app.store.db import make_engine, make_sessionmaker

    engine = make_engine(settings.sqlalchemy_url)
    sessions = make_sessionmaker(engine)
    ensure_ready(settings, engine, sessions, trainer=lambda: base_model, progress=False)
    yield engine, sessions
    engine.dispose()


@pytest.fixture
def dataset(base_model) -> TactileDataset:
    return base_model[1]


@pytest.fixture
def sample(dataset) -> list:
    """One valid sample as JSON-ready nested lists."""
    return copy.deepcopy(dataset.samples[0].tolist())


# a small service on ``best`` (the service's default method; the fixtures above use ``paper``)
BEST_PARAMS = {"seed": 0, "n_estimators": 10, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def best_base():
    dataset = quick_dataset()
    return make_method("best", **BEST_PARAMS).fit(dataset), dataset


@pytest.fixture
def best_service(tmp_path, best_base):
    """(client, app, worker) of a service whose method is ``best`` (SQLite)."""
    from app.api.main import create_app
    from worker import Worker

    app = create_app(
        quick_settings(tmp_path, method="best", method_params=BEST_PARAMS),
        trainer=lambda: best_base,
    )
    with TestClient(app) as client:
        yield (
            client,
            app,
            Worker(
                app.state.service.settings,
                app.state.service.sessions,
                on_activate=app.state.service.holder.serve,
            ),
        )


@pytest.fixture
def best_stores_service(settings, best_base):
    """(client, app, worker) of a ``best`` service on each store (``settings``)."""
    from app.api.main import create_app
    from worker import Worker

    app = create_app(
        settings.model_copy(update={"method": "best", "method_params": BEST_PARAMS}),
        trainer=lambda: best_base,
    )
    with TestClient(app) as client:
        state = app.state.service
        yield client, app, Worker(state.settings, state.sessions, on_activate=state.holder.serve)
