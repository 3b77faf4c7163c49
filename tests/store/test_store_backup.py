"""Store checks, online backup and restore: a backup taken while the service enrols
restores every class, sample and model version it had, and nothing is half-written."""

from __future__ import annotations

import subprocess
import sys
import threading

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import delete

from app.api.main import create_app
from app.cli import main as cli
from app.framework import bundle
from app.store import repo
from app.store.backup import StoreBackupError, backup, restore
from app.store.in_use import StoreInUseError, closed_to_service, lock_path, opened_by_service
from app.store.integrity import check_store
from app.store.models import Bundle
from app.testing.service import list_all, quick_settings, unused_vectors

sqlite_only = pytest.mark.parametrize("settings", ["sqlite"], indirect=True)


def enrol(client, worker, dataset, name: str, index: int, sample) -> None:
    vector = unused_vectors(dataset, index + 1)[index]
    cid = client.post("/v1/classes", json={"name": name, "attribute_vector": vector}).json()[
        "class"
    ]["id"]
    assert client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}).status_code == 202
    assert worker.run_once() == 2


def snapshot(client) -> dict:
    return {
        "classes": list_all(client, "/v1/classes", "classes"),
        "models": list_all(client, "/v1/models", "models"),
        "active": client.get("/v1/models/active").json(),
    }


@sqlite_only
def test_a_backup_taken_while_serving_restores_what_it_had(
    client, worker, dataset, sample, base_model, settings, tmp_path
):
    enrol(client, worker, dataset, "cup", 0, sample)
    before = snapshot(client)
    summary = backup(settings.sqlalchemy_url, tmp_path / "tactile-backup.db")
    assert (summary.active_version, summary.enrolled_samples) == (2, 1)
    assert summary.classes == dataset.n_classes + 1 and summary.versions == 2
    # one self-contained file: no -wal, -shm or .partial beside it
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("tactile-backup")) == [
        "tactile-backup.db"
    ]
    enrol(client, worker, dataset, "mug", 1, sample)  # after the backup: not in it

    restored = quick_settings(tmp_path / "restored")
    assert restore(tmp_path / "tactile-backup.db", restored.sqlalchemy_url) == summary
    assert check_store(restored.sqlalchemy_url) == []
    with TestClient(create_app(restored, trainer=lambda: base_model)) as again:
        assert snapshot(again) == before
        r = again.post("/v1/recognize", json={"samples": [sample]})
        assert r.status_code == 200 and r.json()["model_version"] == 2


@sqlite_only
def test_a_summary_counts_withdrawn_classes_and_samples_apart(
    client, worker, dataset, sample, settings, tmp_path
):
    enrol(client, worker, dataset, "cup", 0, sample)
    enrol(client, worker, dataset, "mug", 1, sample)
    cup, mug = (
        c["id"] for c in list_all(client, "/v1/classes", "classes") if c["name"] in ("cup", "mug")
    )
    mug_sample = client.get(f"/v1/classes/{mug}/samples").json()["samples"][0]["id"]
    assert client.post(f"/v1/classes/{mug}/samples", json={"sample": sample}).status_code == 202
    assert client.delete(f"/v1/classes/{cup}").status_code == 202  # and its one sample
    assert client.delete(f"/v1/classes/{mug}/samples/{mug_sample}").status_code == 202
    summary = backup(settings.sqlalchemy_url, tmp_path / "b.db")
    assert summary.classes == dataset.n_classes + 1 and summary.enrolled_samples == 1
    assert (summary.withdrawn_classes, summary.withdrawn_samples) == (1, 2)
    assert (
        f"{dataset.n_classes + 1} classes, 1 enrolled samples (withdrawn: 1 classes, 2 samples)"
        in str(summary)
    )


@sqlite_only
def test_a_backup_during_enrolments_is_consistent(
    client, worker, dataset, sample, settings, tmp_path
):
    stop = threading.Event()

    def enrol_until_stopped():
        for i in range(6):
            if stop.is_set():
                return
            enrol(client, worker, dataset, f"c{i}", i, sample)

    writer = threading.Thread(target=enrol_until_stopped)
    writer.start()
    try:
        summaries = [backup(settings.sqlalchemy_url, tmp_path / f"b{i}.db") for i in range(3)]
    finally:
        stop.set()
        writer.join()
    for i, summary in enumerate(summaries):
        assert check_store(f"sqlite:///{tmp_path / f'b{i}.db'}") == []
        # each enrolment adds one class, one sample and one version in its own commits
        assert summary.classes - dataset.n_classes >= summary.versions - 1 >= 0


@sqlite_only
def test_a_restore_is_refused_while_the_service_has_the_store_open(
    client, worker, dataset, sample, settings, tmp_path
):
    out = tmp_path / "b.db"
    backup(settings.sqlalchemy_url, out)
    enrol(client, worker, dataset, "cup", 0, sample)  # the live store moves on
    before = snapshot(client)
    with pytest.raises(
        StoreBackupError, match="nothing was restored: .* in use by a running API process"
    ):
        restore(out, settings.sqlalchemy_url, replace=True)
    assert snapshot(client) == before  # untouched: the cup is still there, and still served


def test_replace_puts_the_backup_over_a_stopped_service_s_store(
    base_model, dataset, sample, tmp_path
):
    settings = quick_settings(tmp_path / "data")
    with TestClient(create_app(settings, trainer=lambda: base_model)) as client:
        summary = backup(settings.sqlalchemy_url, tmp_path / "b.db")
        from worker import Worker

        enrol(
            client, Worker(settings, client.app.state.service.sessions), dataset, "cup", 0, sample
        )
    assert restore(tmp_path / "b.db", settings.sqlalchemy_url, replace=True) == summary
    assert check_store(settings.sqlalchemy_url) == []
    with TestClient(create_app(settings, trainer=lambda: base_model)) as client:
        assert "cup" not in {c["name"] for c in list_all(client, "/v1/classes", "classes")}


def test_a_killed_process_does_not_hold_the_store(tmp_path):
    """The kernel drops the lock of a process that dies, even by SIGKILL."""
    url = f"sqlite:///{tmp_path / 'tactile.db'}"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from app.store.in_use import opened_by_service\n"
            f"with opened_by_service({url!r}):\n print('held', flush=True); time.sleep(600)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with (
            pytest.raises(StoreInUseError, match="in use by a running API process or worker"),
            closed_to_service(url),
        ):
            pass
    finally:
        holder.kill()
        holder.wait()
    with closed_to_service(url):  # free at once, with no expiry to wait for
        pass


def test_a_service_starting_during_a_restore_waits_for_it(tmp_path):
    url = f"sqlite:///{tmp_path / 'tactile.db'}"
    opened = threading.Event()

    def start_service():
        with opened_by_service(url):
            opened.set()

    with closed_to_service(url):
        starting = threading.Thread(target=start_service)
        starting.start()
        assert not opened.wait(0.5)  # blocked behind the restore
    assert opened.wait(30)
    starting.join()


def test_stores_that_are_not_sqlite_files_are_not_guarded():
    for url in ("postgresql://postgres@127.0.0.1:5432/test", "sqlite://", "sqlite:///:memory:"):
        assert lock_path(url) is None
        with opened_by_service(url), closed_to_service(url):
            pass


@sqlite_only
def test_bad_backups_and_restores_are_refused_and_write_nothing(client, settings, tmp_path):
    out = tmp_path / "b.db"
    backup(settings.sqlalchemy_url, out)
    with pytest.raises(StoreBackupError, match="exists already"):
        backup(settings.sqlalchemy_url, out)
    with pytest.raises(StoreBackupError, match="does not exist"):
        backup(settings.sqlalchemy_url, tmp_path / "no" / "b.db")
    with pytest.raises(StoreBackupError, match="pg_dump"):
        backup("postgresql://postgres@127.0.0.1:5432/test", tmp_path / "pg.db")
    with pytest.raises(StoreBackupError, match="holds a store already; pass --replace"):
        restore(out, settings.sqlalchemy_url)

    damaged = tmp_path / "damaged.db"
    damaged.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
    target = quick_settings(tmp_path / "fresh")
    with pytest.raises(StoreBackupError, match="fails its checks, nothing was restored"):
        restore(damaged, target.sqlalchemy_url)
    assert not (tmp_path / "fresh" / "tactile.db").exists()
    with pytest.raises(StoreBackupError, match="there is no backup"):
        restore(tmp_path / "missing.db", target.sqlalchemy_url)


def test_cli_check_names_the_problem_and_fails(store, settings, monkeypatch, capsys):
    """On both stores: a clean store passes; one missing a bundle part fails, named."""
    _, sessions = store
    monkeypatch.setenv("TACTILE_DATABASE_URL", settings.sqlalchemy_url)
    assert cli(["store", "check"]) == 0
    assert "passes every check" in capsys.readouterr().out
    with sessions.begin() as s:
        head = repo.bundle_data(s, repo.active_version(s).bundle_sha256)
        s.execute(delete(Bundle).where(Bundle.sha256 == next(iter(bundle.part_shas(head)))))
    assert cli(["store", "check"]) == 1
    assert (
        "problem: version 1 refers to bundle parts that are not stored" in capsys.readouterr().out
    )


@sqlite_only
def test_cli_backs_up_and_restores(client, settings, monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("TACTILE_DATABASE_URL", settings.sqlalchemy_url)
    assert cli(["store", "backup", str(tmp_path / "b.db")]) == 0
    assert "backed up" in capsys.readouterr().out
    assert cli(["store", "backup", str(tmp_path / "b.db")]) == 2
    assert "exists already" in capsys.readouterr().err
    monkeypatch.setenv("TACTILE_DATABASE_URL", f"sqlite:///{tmp_path / 'other.db'}")
    assert cli(["store", "restore", str(tmp_path / "b.db")]) == 0
    assert (
        "restored" in capsys.readouterr().out
        and check_store(f"sqlite:///{tmp_path / 'other.db'}") == []
    )
