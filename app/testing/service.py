"""A quick service for tests and benchmarks: one small model trained once per process
(``trained_base``), its settings (``quick_settings``), fresh PostgreSQL databases and
``tactile-zsl store check`` run as an operator runs it.

The pytest fixtures built on these (``client``, ``worker``, ``store``, ...) are in
``tests/service_fixtures.py``.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import os
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import app
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

# a small service on ``best`` (the service's default method; the quick one above is ``paper``)
BEST_PARAMS = {"seed": 0, "n_estimators": 10, "tuning_rounds": 1, "distance_components": 8}


def quick_dataset() -> TactileDataset:
    from app.data.simulator import simulate_dataset

    return simulate_dataset(n_objects=QUICK_OBJECTS, trials_per_object=QUICK_TRIALS, seed=0)


@functools.cache
def _train_once() -> tuple[TactileRecognizer, TactileDataset]:
    dataset = quick_dataset()
    return make_method(QUICK_METHOD, **QUICK_PARAMS).fit(dataset), dataset


def trained_base() -> tuple[TactileRecognizer, TactileDataset]:
    """The one quick model of this process (the store only serialises it)."""
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


def quick_settings(data_dir, **overrides) -> Settings:
    values = {
        "data_dir": data_dir,
        "embedded_worker": False,
        "dataset": QUICK_DATASET,
        "method": QUICK_METHOD,
        "method_params": {QUICK_METHOD: QUICK_PARAMS},
        "model_poll_seconds": 0.05,
        "worker_poll_seconds": 0.05,
        "lease_seconds": 10.0,
        "promotion_threshold": 10,
        # 0.5 GB and 4 s of CPU per app; the tests of descriptions load it when they read one
        "warm_words": False,
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
        # the folder holding this ``app`` package, so that the child runs the same code
        cwd=Path(app.__file__).resolve().parents[1],
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
