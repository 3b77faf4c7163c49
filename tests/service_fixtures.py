"""Fixtures shared by tests/api, tests/store, tests/worker and the end-to-end test, and the
request helpers of the service tests.

One small model is trained once per test process (``app.testing.service.trained_base``) and
every test's fresh store is bootstrapped from it, so no test waits for training except the
few that retrain on purpose. What bench/ shares with these tests (the quick model, its
settings, fresh databases) is in ``app.testing``; the pytest fixtures stay here.
"""

from __future__ import annotations

import copy
import functools
import io
import os
import time
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.data.dataset import TactileDataset
from app.framework.recognizer import TactileRecognizer
from app.framework.registry import make_method
from app.testing.service import (
    BEST_PARAMS,
    fresh_postgres_database,
    names_of,
    quick_dataset,
    quick_settings,
    trained_base,
    unused_vectors,
)

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
        quick_settings(tmp_path, method="best", method_params={"best": BEST_PARAMS}),
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
        settings.model_copy(update={"method": "best", "method_params": {"best": BEST_PARAMS}}),
        trainer=lambda: best_base,
    )
    with TestClient(app) as client:
        state = app.state.service
        yield client, app, Worker(state.settings, state.sessions, on_activate=state.holder.serve)


def refit_stopped(client, app, worker, dataset, **limit) -> tuple[int, int, dict, list]:
    """Register class 'heavy', give it 2 samples so that the next one promotes it (every
    promotion refits), set the settings ``limit`` (e.g. ``refit_seconds=2``) and add that
    sample in a worker round run in a thread while this one recognises. Returns (class id,
    the version active before, the last sample's answer, [(status, model_version) of each
    recognition meanwhile])."""
    import threading

    settings = app.state.service.settings
    settings.promotion_threshold = 2
    settings.grow_fraction = 0  # every promotion refits
    cid = register(client, dataset, "heavy")["class"]["id"]
    worker.run_once()
    add_sample(client, cid, dataset.samples[0] + 0.01)
    worker.run_once()
    active = client.get("/v1/models/active").json()["version"]
    for name, value in limit.items():
        setattr(settings, name, value)
    last = add_sample(client, cid, dataset.samples[1] + 0.01)
    finished = []
    round_ = threading.Thread(target=lambda: finished.append(worker.run_once()))
    round_.start()
    answers = []
    while round_.is_alive():  # the refit's child runs meanwhile
        r = client.post("/v1/recognize", json={"samples": [dataset.samples[2].tolist()]})
        answers.append((r.status_code, r.json().get("model_version")))
    round_.join()
    assert finished == [1]
    return cid, active, last, answers


def live_channel(dataset) -> int:
    """The channel that reads farthest from 0 in training: one that goes dead (reads 0) is a
    fault, where a channel that reads near 0 anyway looks alike dead or alive. The quick
    model's profile holds 60 samples, so its threshold comes from them (12.3 here, not 2.5:
    ``app.framework.input_health``), and a channel that read near 0 went unflagged."""
    levels = np.abs(dataset.samples.reshape(len(dataset.samples), dataset.samples.shape[1], -1))
    return int(np.argmax(levels.mean(axis=(0, 2))))
