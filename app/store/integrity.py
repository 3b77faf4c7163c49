"""Integrity of a store: what must hold whatever was killed, when.

SQLite's own ``integrity_check`` and ``foreign_key_check``, then the same consistency
queries on both databases: one active version, no dangling references, every bundle's
hash matches its bytes, and every version's bundle parts are stored. Used by
``tactile-zsl store check``, by ``store backup`` on its copy, and by the crash tests.
"""

from __future__ import annotations

import hashlib

from sqlalchemy import Engine, text
from sqlalchemy.exc import DatabaseError

from app.framework import bundle
from app.store.db import make_engine
from app.store.enums import JobStatus

CONSISTENCY = {
    "active versions != 1": "SELECT COUNT(*) <> 1 FROM model_versions WHERE active",
    "samples of missing classes": (
        "SELECT COUNT(*) > 0 FROM samples s LEFT JOIN classes c ON c.id = s.class_id "
        "WHERE c.id IS NULL"
    ),
    "jobs of missing samples": (
        "SELECT COUNT(*) > 0 FROM jobs j LEFT JOIN samples s ON s.id = j.sample_id "
        "WHERE j.sample_id IS NOT NULL AND s.id IS NULL"
    ),
    "versions without bundle": (
        "SELECT COUNT(*) > 0 FROM model_versions v "
        "LEFT JOIN bundles b ON b.sha256 = v.bundle_sha256 WHERE b.sha256 IS NULL"
    ),
    "succeeded jobs without version": (
        f"SELECT COUNT(*) > 0 FROM jobs WHERE status = '{JobStatus.SUCCEEDED}' "
        "AND model_version IS NULL"
    ),
}


def check_store(target: str | Engine) -> list[str]:
    """The problems found in the store at ``target`` (a URL or an engine); [] if none."""
    engine = make_engine(target) if isinstance(target, str) else target
    problems: list[str] = []
    try:
        _check(engine, problems)
    except DatabaseError as exc:  # a damaged file, or a server that cannot be reached
        problems.append(f"the store cannot be read: {exc.orig}")
    finally:
        if isinstance(target, str):
            engine.dispose()
    return problems


def _check(engine: Engine, problems: list[str]) -> None:
    with engine.connect() as conn:
        if conn.dialect.name == "sqlite":
            result = conn.exec_driver_sql("PRAGMA integrity_check").scalar()
            if result != "ok":
                problems.append(f"integrity_check: {result}")
            if conn.exec_driver_sql("PRAGMA foreign_key_check").first() is not None:
                problems.append("foreign_key_check found dangling rows")
        for name, sql in CONSISTENCY.items():
            if conn.execute(text(sql)).scalar():
                problems.append(name)
        # one bundle row in memory at a time: a store may hold hundreds of megabytes
        rows = conn.execution_options(stream_results=True, yield_per=1).execute(
            text("SELECT sha256, data FROM bundles")
        )
        damaged = {sha for sha, data in rows if hashlib.sha256(bytes(data)).hexdigest() != sha}
        stored = set(conn.execute(text("SELECT sha256 FROM bundles")).scalars())
        heads = conn.execution_options(stream_results=True, yield_per=1).execute(
            text(
                "SELECT v.version, v.bundle_sha256, b.data FROM model_versions v "
                "JOIN bundles b ON b.sha256 = v.bundle_sha256 ORDER BY v.version"
            )
        )
        users: dict[str, list[str]] = {sha: [] for sha in damaged}  # what each damaged one is
        for version, head_sha, data in heads:
            if head_sha in damaged:
                users[head_sha].append(f"the model of version {version}")
            try:
                refs = bundle.part_shas(bytes(data))
            except Exception as exc:  # a damaged head may not even parse
                problems.append(f"version {version}: its bundle cannot be read ({exc})")
                continue
            if refs - stored:
                problems.append(f"version {version} refers to bundle parts that are not stored")
            for sha in refs & damaged:
                users[sha].append(f"a part of version {version}")
        for sha in sorted(damaged):
            used = "; ".join(users[sha]) or "used by no version"
            problems.append(f"bundle {sha[:12]} does not match its hash ({used})")
