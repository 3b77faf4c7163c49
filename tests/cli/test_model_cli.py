"""``tactile-zsl model choose`` queues the job that ``POST /v1/models/choice`` queues, on
the store the settings name, and refuses a fixed method with exit 2."""

from __future__ import annotations

import os
import subprocess
import sys

from sqlalchemy import select

from app.store.db import make_engine, make_sessionmaker
from app.store.enums import JobKind, JobStatus
from app.store.models import Job


def _choose(tmp_path, method: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "TACTILE_DATA_DIR": str(tmp_path), "TACTILE_METHOD": method}
    env.pop("TACTILE_DATABASE_URL", None)
    env.pop("TACTILE_METHOD_PARAMS", None)
    return subprocess.run(
        [sys.executable, "-m", "app.cli", "model", "choose"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_choose_queues_a_choose_method_job(tmp_path):
    done = _choose(tmp_path, "auto")
    assert done.returncode == 0, done.stderr
    assert "queued" in done.stdout
    engine = make_engine(f"sqlite:///{tmp_path / 'tactile.db'}")
    with make_sessionmaker(engine)() as s:
        jobs = s.scalars(select(Job)).all()
    assert [(j.kind, j.status, j.requested_by) for j in jobs] == [
        (JobKind.CHOOSE_METHOD, JobStatus.QUEUED, "cli")
    ]


def test_a_fixed_method_exits_2_naming_the_setting(tmp_path):
    done = _choose(tmp_path, "best")
    assert done.returncode == 2
    assert "TACTILE_METHOD" in done.stderr and "not 'auto'" in done.stderr
