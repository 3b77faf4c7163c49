"""Model versions (which one is active, their lineage) and the bundle bytes they point to."""

from __future__ import annotations

import hashlib

from sqlalchemy import LargeBinary, func, select, update
from sqlalchemy.orm import Session, defer, with_expression

from app.framework.errors import BundleError
from app.store.models import Bundle, ModelVersion

# ------------------------------------------------------------ model versions


def active_version_number(session: Session) -> int | None:
    """The cheap poll every API process runs: one indexed row."""
    return session.scalar(select(ModelVersion.version).where(ModelVersion.active))


def active_version(session: Session) -> ModelVersion | None:
    return session.scalar(select(ModelVersion).where(ModelVersion.active))


def get_version(session: Session, version: int) -> ModelVersion | None:
    return session.get(ModelVersion, version)


def list_versions(
    session: Session, after: int | None = None, limit: int | None = None, summary: bool = False
) -> list[ModelVersion]:
    """Versions, oldest first; with ``after``, those after it; at most ``limit``. With
    ``summary``, the class and sample lists (thousands of entries per version in a
    long-running fleet) stay unread and the database counts the classes."""
    stmt = select(ModelVersion).order_by(ModelVersion.version).limit(limit)
    if summary:
        stmt = stmt.options(
            defer(ModelVersion.classes),
            defer(ModelVersion.sample_ids),
            with_expression(
                ModelVersion.counted_classes, func.json_array_length(ModelVersion.classes)
            ),
        )
    if after is not None:
        stmt = stmt.where(ModelVersion.version > after)
    return list(session.scalars(stmt))


def add_version(session: Session, **fields) -> ModelVersion:
    row = ModelVersion(active=False, **fields)
    session.add(row)
    session.flush()
    return row


def activate(session: Session, version: int) -> bool:
    """Make ``version`` the active one; False, and the caller must roll back, if there is
    no such version (pruned since it was read), as no version is active then."""
    # clear first: the partial unique index allows one active row at any instant
    session.execute(
        update(ModelVersion)
        .where(ModelVersion.active, ModelVersion.version != version)
        .values(active=False)
    )
    done = session.execute(
        update(ModelVersion).where(ModelVersion.version == version).values(active=True)
    )
    return done.rowcount == 1


def stored_model_figures(session: Session) -> tuple[int, int]:
    """(model versions, bytes of bundle rows) the store holds: what retention bounds."""
    versions = session.scalar(select(func.count()).select_from(ModelVersion))
    size = session.scalar(select(func.coalesce(func.sum(Bundle.size), 0)))
    return int(versions), int(size)


# ------------------------------------------------------------------- bundles

# Bundles are read in slices: a database driver converts a whole value while it holds the
# GIL, so reading a 3.3 MB bundle through psycopg2 held an API process's event loop (and
# every request in it) for up to 9 ms each time it loaded a new model version; in 256 kB
# slices, at most 3 ms.
BUNDLE_READ_BYTES = 256 * 1024


def bundle_data(session: Session, sha256: str) -> bytes | None:
    """The bytes of bundle ``sha256`` (None if there is none), checked against their hash."""
    size = session.scalar(select(Bundle.size).where(Bundle.sha256 == sha256))
    if size is None:
        return None
    parts = [
        session.scalar(
            select(func.substr(Bundle.data, start + 1, BUNDLE_READ_BYTES, type_=LargeBinary)).where(
                Bundle.sha256 == sha256
            )
        )
        for start in range(0, size, BUNDLE_READ_BYTES)
    ]
    data = b"".join(parts)  # LargeBinary gives bytes on every driver
    if len(data) != size or hashlib.sha256(data).hexdigest() != sha256:
        raise BundleError(
            f"stored bundle {sha256[:12]}… reads back as {len(data)} bytes of "
            f"{size} with another hash: the store is damaged"
        )
    return data


def store_bundle(session: Session, data: bytes, sha256: str | None = None) -> str:
    """Content-addressed: identical bundles (and bundle parts) are stored once. ``sha256``,
    when the caller has it already, must be the SHA-256 of ``data``."""
    sha = sha256 or hashlib.sha256(data).hexdigest()
    # only the key: session.get would read the whole stored bundle back
    if session.scalar(select(Bundle.sha256).where(Bundle.sha256 == sha)) is None:
        session.add(Bundle(sha256=sha, size=len(data), data=data))
        session.flush()
    return sha
