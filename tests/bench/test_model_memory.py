"""``bench.model_memory`` on a small store: it names the version it loaded and the bytes
of the model's arrays, its forests' node records among them and their leaf redirects (none
for a model no promotion grew), and a folder without a model is an error."""

import re

import pytest

from app.framework.registry import make_method
from app.service.bootstrap import ensure_ready
from app.store.db import make_engine, make_sessionmaker
from app.testing.service import quick_dataset, quick_settings
from bench import model_memory


def test_it_reports_the_active_models_memory(tmp_path, capsys):
    settings = quick_settings(tmp_path / "data")
    engine = make_engine(settings.sqlalchemy_url)
    dataset = quick_dataset()
    model = make_method("best", n_estimators=10, seed=0).fit(dataset)  # forests
    ensure_ready(
        settings,
        engine,
        make_sessionmaker(engine),
        trainer=lambda: (model, dataset),
        progress=False,
    )
    engine.dispose()
    model_memory.main(["--data-dir", str(tmp_path / "data")])
    out = capsys.readouterr().out
    assert f"model version 1 ({len(model.registry.known_names)} known classes)" in out
    arrays, records = map(
        float, re.search(r"arrays (\S+) MB, of which forest node records (\S+) MB", out).groups()
    )
    redirects = float(re.search(r"leaf redirects \(made by promotions\) (\S+) MB", out).group(1))
    assert 0 < records < arrays and redirects == 0


def test_a_folder_without_a_model_is_refused(tmp_path):
    settings = quick_settings(tmp_path / "empty")
    engine = make_engine(settings.sqlalchemy_url)
    from app.store import migrate

    migrate.upgrade(engine)
    engine.dispose()
    with pytest.raises(SystemExit) as exc:
        model_memory.main(["--data-dir", str(tmp_path / "empty")])
    assert exc.value.code == 2
