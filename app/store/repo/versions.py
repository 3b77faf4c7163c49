"""Model versions (which one is active, their lineage) and the bundle bytes they point to."""

from __future__ import annotations

import hashlib
import sqlite3

from sqlalchemy import Connection, Integer, LargeBinary, func, literal_column, select, true, update
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

# A bundle is read with one statement, at a cost that grows with its size, and no driver
# call copies the whole value while it holds the GIL, as every request of an API process
# waits meanwhile (psycopg2 converting a whole 3.3 MB bundle: up to 9 ms, cba0e37; a 50 MB
# part: ~75 ms). PostgreSQL sends the value as rows of BUNDLE_READ_BYTES slices through a
# server-side cursor, a few rows per round trip, each converted on its own (a 50 MB part:
# 0.4 s, as with a statement per slice); SQLite copies it through its incremental blob
# reader, which releases the GIL (0.1 s). The statement per slice this replaced cost the
# square of the size on SQLite, which reads the whole value for each slice: 11 s.
BUNDLE_READ_BYTES = 256 * 1024
_KEYS_PER_QUERY = 500  # bundle keys looked up in one query (SQLite allows 32,766 variables)
_ROWS_PER_FLUSH = 32  # bundle parts (up to 2 MiB each) inserted in one flush
_SLICES_PER_FETCH = 2  # slices a server-side cursor hands over per round trip


def bundle_data(session: Session, sha256: str) -> bytes | None:
    """The bytes of bundle ``sha256`` (None if there is none), checked against their hash;
    one statement, whatever their size."""
    conn = session.connection()
    read = {"postgresql": _read_sliced, "sqlite": _read_blob}.get(conn.dialect.name, _read_whole)
    try:
        return _checked(read(conn, sha256), sha256)
    except BundleError:
        if read is not _read_blob:
            raise
    # the blob reader found the row by its rowid, which a row written since that lookup
    # may have taken: the value itself decides
    return _checked(_read_whole(conn, sha256), sha256)


def _checked(found: tuple[int, bytes] | None, sha256: str) -> bytes | None:
    if found is None:
        return None
    size, data = found
    if len(data) != size or hashlib.sha256(data).hexdigest() != sha256:
        raise BundleError(
            f"stored bundle {sha256[:12]}… reads back as {len(data)} bytes of "
            f"{size} with another hash: the store is damaged"
        )
    return data


def _read_whole(conn: Connection, sha256: str) -> tuple[int, bytes] | None:
    row = conn.execute(select(Bundle.size, Bundle.data).where(Bundle.sha256 == sha256)).first()
    return None if row is None else (row.size, row.data or b"")


def _read_sliced(conn: Connection, sha256: str) -> tuple[int, bytes] | None:
    n = BUNDLE_READ_BYTES
    pos = func.generate_series(0, func.greatest(Bundle.size - 1, 0, type_=Integer) // n)
    pos = pos.table_valued("i").render_derived(name="slice")
    stmt = (
        select(Bundle.size, func.substr(Bundle.data, pos.c.i * n + 1, n, type_=LargeBinary))
        .join(pos, true())
        .where(Bundle.sha256 == sha256)
        .order_by(pos.c.i)
    )
    options = {"stream_results": True, "max_row_buffer": _SLICES_PER_FETCH}
    size, slices = None, []
    with conn.execute(stmt, execution_options=options) as rows:  # closes the cursor
        for row in rows:
            size = row.size
            slices.append(row[1] or b"")
    # a join of bytes objects releases the GIL while it copies
    return None if size is None else (size, b"".join(slices))


def _read_blob(conn: Connection, sha256: str) -> tuple[int, bytes] | None:
    row = conn.execute(
        select(literal_column("rowid"), Bundle.size).where(Bundle.sha256 == sha256)
    ).first()
    if row is None:
        return None
    rowid, size = row
    try:
        with conn.connection.dbapi_connection.blobopen(
            Bundle.__tablename__, "data", rowid, readonly=True
        ) as blob:
            return size, blob.read()
    except sqlite3.Error:  # gone since the lookup, or not a blob: the value itself decides
        return _read_whole(conn, sha256)


def store_bundles(session: Session, blobs: dict[str, bytes]) -> None:
    """``store_bundle`` of each ``{SHA-256: data}``, asking for the stored keys in batches:
    a version at 10,000 objects has ~1,000 parts, nearly all of them stored already, and a
    query each took a quarter of a second of every enrolment."""
    shas = list(blobs)
    stored: set[str] = set()
    for lo in range(0, len(shas), _KEYS_PER_QUERY):
        batch = shas[lo : lo + _KEYS_PER_QUERY]
        stored.update(session.scalars(select(Bundle.sha256).where(Bundle.sha256.in_(batch))))
    new = [sha for sha in shas if sha not in stored]
    for lo in range(0, len(new), _ROWS_PER_FLUSH):  # inserts of bounded size
        session.add_all(
            Bundle(sha256=sha, size=len(blobs[sha]), data=blobs[sha])
            for sha in new[lo : lo + _ROWS_PER_FLUSH]
        )
        session.flush()


def store_bundle(session: Session, data: bytes, sha256: str | None = None) -> str:
    """Content-addressed: identical bundles (and bundle parts) are stored once. ``sha256``,
    when the caller has it already, must be the SHA-256 of ``data``."""
    sha = sha256 or hashlib.sha256(data).hexdigest()
    # only the key: session.get would read the whole stored bundle back
    if session.scalar(select(Bundle.sha256).where(Bundle.sha256 == sha)) is None:
        session.add(Bundle(sha256=sha, size=len(data), data=data))
        session.flush()
    return sha
