"""Online backup and restore of the SQLite store, through SQLite's own backup API.

A copy is taken in one read transaction, so the service keeps recognising and enrolling
while it runs (WAL readers never block the writer), and it is complete and consistent as
of one commit. The copy is checked (``integrity.check_store``) under a temporary name and
only then renamed into place: a failed or interrupted backup leaves no file that looks
like a good one. A restore checks the backup first, is refused while an API process or
worker has the store open (``in_use``), and replaces the store in one write transaction.
PostgreSQL stores are backed up with its own tools (``pg_dump``).
"""

from __future__ import annotations

import os
import sqlite3
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import create_engine
from sqlalchemy.engine import make_url

from app.store.enums import Origin
from app.store.in_use import StoreInUseError, closed_to_service
from app.store.integrity import check_store

BUSY_MS = 30_000


class StoreBackupError(ValueError):
    """A backup or restore that cannot be done; the message says why."""


@dataclass(frozen=True)
class StoreSummary:
    classes: int  # live ones: withdrawn classes and samples are counted apart
    enrolled_samples: int
    versions: int
    active_version: int | None
    bytes: int
    withdrawn_classes: int = 0
    withdrawn_samples: int = 0

    def __str__(self) -> str:
        withdrawn = (
            f" (withdrawn: {self.withdrawn_classes} classes, {self.withdrawn_samples} samples)"
            if self.withdrawn_classes or self.withdrawn_samples
            else ""
        )
        return (
            f"{self.classes} classes, {self.enrolled_samples} enrolled samples{withdrawn}, "
            f"{self.versions} model versions (active: {self.active_version}), {self.bytes:,} bytes"
        )


def sqlite_path(url: str) -> Path:
    """The file of a SQLite store URL; any other store is refused with what to use instead."""
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        raise StoreBackupError(
            f"the store is {parsed.get_backend_name()}, not SQLite: back it up "
            "with the database's own tools (PostgreSQL: pg_dump -Fc, pg_restore)"
        )
    if not parsed.database or parsed.database == ":memory:":
        raise StoreBackupError(
            "the store is an in-memory SQLite database: there is nothing to back up"
        )
    return Path(parsed.database)


def _problems(path: Path) -> list[str]:
    engine = create_engine(f"sqlite:///{path}")  # no WAL pragma: the file stays one file
    try:
        return check_store(engine)
    finally:
        engine.dispose()


def summarize(path: Path) -> StoreSummary:
    with closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as conn:
        one = lambda sql: conn.execute(sql).fetchone()[0]  # noqa: E731
        # stores from before migration 0004 have no withdrawals
        withdrawals = "withdrawn_at" in {
            row[1] for row in conn.execute("PRAGMA table_info(classes)")
        }
        live, gone = (
            ("withdrawn_at IS NULL", "withdrawn_at IS NOT NULL") if withdrawals else ("1", "0")
        )
        enrolled = f"SELECT COUNT(*) FROM samples WHERE origin = '{Origin.ENROLLED}' AND "
        return StoreSummary(
            classes=one(f"SELECT COUNT(*) FROM classes WHERE {live}"),
            enrolled_samples=one(enrolled + live),
            versions=one("SELECT COUNT(*) FROM model_versions"),
            active_version=one("SELECT MAX(version) FROM model_versions WHERE active"),
            # pages, not the file's size: in WAL mode recent pages may still be in the -wal file
            bytes=one("PRAGMA page_count") * one("PRAGMA page_size"),
            withdrawn_classes=one(f"SELECT COUNT(*) FROM classes WHERE {gone}"),
            withdrawn_samples=one(enrolled + gone),
        )


def backup(url: str, out: Path) -> StoreSummary:
    """Copy the live SQLite store at ``url`` to ``out`` (which must not exist yet)."""
    source = sqlite_path(url)
    if not source.is_file():
        raise StoreBackupError(f"there is no store at {source}")
    out = Path(out)
    if out.exists():
        raise StoreBackupError(f"{out} exists already; choose a new file name")
    if not out.parent.is_dir():
        raise StoreBackupError(f"the folder {out.parent} does not exist")
    partial = out.with_name(out.name + ".partial")
    partial.unlink(missing_ok=True)
    try:
        with (
            closing(sqlite3.connect(source, timeout=BUSY_MS / 1000)) as src,
            closing(sqlite3.connect(partial)) as dst,
        ):
            src.backup(dst)  # all pages in one step: one read transaction, one consistent copy
            dst.execute("PRAGMA journal_mode=DELETE")  # a self-contained file, no -wal beside it
        problems = _problems(partial)
        if problems:
            raise StoreBackupError(f"the copy of {source} fails its checks: {'; '.join(problems)}")
        summary = summarize(partial)
        os.replace(partial, out)
    finally:
        partial.unlink(missing_ok=True)
    return summary


def restore(backup_file: Path, url: str, replace: bool = False) -> StoreSummary:
    """Replace the SQLite store at ``url`` by ``backup_file``, after checking the backup.
    A store that already holds data is only replaced with ``replace``."""
    target = sqlite_path(url)
    backup_file = Path(backup_file)
    if not backup_file.is_file():
        raise StoreBackupError(f"there is no backup at {backup_file}")
    problems = _problems(backup_file)
    if problems:
        raise StoreBackupError(
            f"{backup_file} fails its checks, nothing was restored: {'; '.join(problems)}"
        )
    if target.exists() and target.stat().st_size > 0 and not replace:
        raise StoreBackupError(
            f"{target} holds a store already; pass --replace to overwrite it "
            "(stop every API process and worker first)"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        with (
            closed_to_service(url),
            closing(sqlite3.connect(f"file:{backup_file}?mode=ro", uri=True)) as src,
            closing(sqlite3.connect(target, timeout=BUSY_MS / 1000)) as dst,
        ):
            src.backup(dst)  # one write transaction: the old store or the new one, never a mix
    except StoreInUseError as exc:
        raise StoreBackupError(f"nothing was restored: {exc}") from None
    return summarize(target)
