"""Two real processes starting at once on an empty store: exactly one trains the base
model, on each store."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from sqlalchemy import func, select

from app.framework import bundle
from app.store.db import make_engine, make_sessionmaker
from app.store.models import ModelVersion, ObjectClass

ROOT = Path(__file__).resolve().parents[2]

START = r"""
import json, os, sys, time
from app.config import Settings
from app.framework import bundle
from app.service.bootstrap import ensure_ready
from app.store.db import make_engine, make_sessionmaker
from app.testing.service import quick_dataset

settings = Settings(**json.loads(sys.argv[1]))
marks = sys.argv[3]

def trainer():
    open(os.path.join(marks, f"trained-{os.getpid()}"), "w").close()
    time.sleep(1.0)  # hold the bootstrap lease a while
    with open(sys.argv[2], "rb") as fh:
        return bundle.from_bytes(fh.read()), quick_dataset()

engine = make_engine(settings.sqlalchemy_url)
print(ensure_ready(settings, engine, make_sessionmaker(engine), trainer=trainer, progress=False))
"""


def test_two_processes_starting_at_once_bootstrap_once(settings, base_model, tmp_path):
    model, dataset = base_model
    model_file = tmp_path / "base.bundle"
    model_file.write_bytes(bundle.to_bytes(model))
    marks = tmp_path / "marks"
    marks.mkdir()
    config = json.dumps({"database_url": settings.sqlalchemy_url, "data_dir": str(tmp_path)})
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", START, config, str(model_file), str(marks)],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=180) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-2000:] for _, err in outs]
    assert [out.strip().splitlines()[-1] for out, _ in outs] == ["1", "1"]
    assert len(list(marks.iterdir())) == 1  # one of them trained
    engine = make_engine(settings.sqlalchemy_url)
    with make_sessionmaker(engine)() as s:
        assert s.scalar(select(func.count()).select_from(ModelVersion)) == 1
        assert s.scalar(select(func.count()).select_from(ObjectClass)) == dataset.n_classes
    engine.dispose()
