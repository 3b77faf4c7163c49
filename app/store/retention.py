"""Retention of model versions: every enrollment adds a version, so old ones are pruned.

A pruned version is no longer listed and cannot be activated (rolled back to); the
classes, samples and jobs it was built from stay. Kept are the ``keep`` newest versions,
the active one (which an earlier version may be, after a rollback) and the bootstrap
version, the model the store started from. Bundle rows (heads and parts) that no kept
version uses are deleted with them.

The caller must hold the retrain lease: no other process writes versions or bundles
meanwhile, so a part that no kept head names cannot be about to be named by one.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from app.framework import bundle
from app.store import repo
from app.store.enums import VersionReason
from app.store.models import Bundle, ModelVersion


@dataclass(frozen=True)
class Pruned:
    versions: list[int]
    bundles: int  # rows deleted: heads and parts
    bytes: int

    def __bool__(self) -> bool:
        return bool(self.versions)


NOTHING = Pruned([], 0, 0)


def prunable(session: Session, keep: int) -> list[int]:
    """The versions ``prune`` would delete, oldest first."""
    if keep < 1:
        raise ValueError(f"keep must be at least 1, got {keep}")
    rows = session.execute(
        select(ModelVersion.version, ModelVersion.active, ModelVersion.reason).order_by(
            ModelVersion.version.desc()
        )
    ).all()
    return sorted(
        v
        for i, (v, active, reason) in enumerate(rows)
        if i >= keep and not active and reason != VersionReason.BOOTSTRAP
    )


def prune(
    session: Session, keep: int, slack: int = 0, part_refs: dict[str, set[str]] | None = None
) -> Pruned:
    """Delete the versions beyond the ``keep`` newest (see the module docstring) and
    the bundle rows only they used; nothing while at most ``slack`` versions are over.

    The slack spreads the work: finding unused parts reads every kept head. So does
    ``part_refs``, {head SHA-256: its parts}, kept by the caller between prunes: heads
    never change, so only those stored since the last prune are read.
    """
    doomed = prunable(session, keep)
    if len(doomed) <= slack:
        return NOTHING
    for chunk in _chunks(doomed):
        # "not active" again in the statement: an activation may have committed since
        session.execute(
            delete(ModelVersion).where(ModelVersion.version.in_(chunk), ~ModelVersion.active)
        )
    kept = set(session.scalars(select(ModelVersion.version)))
    deleted = [v for v in doomed if v not in kept]
    if not deleted:
        return NOTHING
    heads = set(session.scalars(select(ModelVersion.bundle_sha256).distinct()))
    refs = {} if part_refs is None else part_refs
    for head in heads - refs.keys():
        # a damaged head raises: its parts are unknown, so none may go (the caller rolls back)
        refs[head] = bundle.part_shas(repo.bundle_data(session, head))
    for head in refs.keys() - heads:
        del refs[head]
    used = heads.union(*(refs[h] for h in heads))
    unused = [sha for sha in session.scalars(select(Bundle.sha256)) if sha not in used]
    size = 0
    for chunk in _chunks(unused):
        size += session.scalar(
            select(func.coalesce(func.sum(Bundle.size), 0)).where(Bundle.sha256.in_(chunk))
        )
        session.execute(delete(Bundle).where(Bundle.sha256.in_(chunk)))
    return Pruned(deleted, len(unused), int(size))


def _chunks(items: list, size: int = 500):
    """IN lists of bounded length (SQLite limits a statement's parameters)."""
    for start in range(0, len(items), size):
        yield items[start : start + size]
