"""API keys (only their hashes are stored) and the answers kept for Idempotency-Keys."""

from __future__ import annotations

import hashlib
import secrets
from datetime import datetime

from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from app.store.models import ApiKey, IdempotencyRecord, utcnow

# ------------------------------------------------------------------ API keys

SCOPES = ("read", "enroll", "admin")  # each includes the rights of those before it
KEY_PREFIX = "tzk_"


def hash_key(key: str) -> str:
    """Keys are 256-bit random strings, so a plain SHA-256 is a safe way to store them."""
    return hashlib.sha256(key.encode()).hexdigest()


def create_api_key(session: Session, scope: str, name: str | None = None) -> tuple[str, ApiKey]:
    """A new key (returned once, never stored) and its row."""
    if scope not in SCOPES:
        raise ValueError(f"scope must be one of {', '.join(SCOPES)}, not '{scope}'")
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    row = ApiKey(key_sha256=hash_key(key), prefix=key[:12], scope=scope, name=name)
    session.add(row)
    session.flush()
    return key, row


def list_api_keys(session: Session) -> list[ApiKey]:
    return list(session.scalars(select(ApiKey).order_by(ApiKey.id)))


def revoke_api_key(session: Session, key_id: int) -> bool:
    res = session.execute(
        update(ApiKey)
        .where(ApiKey.id == key_id, ApiKey.revoked_at.is_(None))
        .values(revoked_at=utcnow())
    )
    return (res.rowcount or 0) == 1


def api_key_table(session: Session) -> tuple[bool, dict[str, tuple[int, str]]]:
    """(whether any key was ever created, {sha256: (id, scope)} of the usable ones)."""
    rows = session.execute(select(ApiKey.id, ApiKey.key_sha256, ApiKey.scope, ApiKey.revoked_at))
    any_key, usable = False, {}
    for key_id, sha, scope, revoked in rows:
        any_key = True
        if revoked is None:
            usable[sha] = (key_id, scope)
    return any_key, usable


# ------------------------------------------------------------- idempotency


def get_idempotency(session: Session, principal: str, key: str) -> IdempotencyRecord | None:
    return session.get(IdempotencyRecord, (principal, key))


def add_idempotency(
    session: Session,
    principal: str,
    key: str,
    fingerprint: str,
    status_code: int,
    body: dict,
    location: str | None,
) -> None:
    """Flushed at once: a concurrent request with the same key fails here (IntegrityError)."""
    session.add(
        IdempotencyRecord(
            principal=principal,
            key=key,
            fingerprint=fingerprint,
            status_code=status_code,
            body=body,
            location=location,
        )
    )
    session.flush()


def purge_idempotency(session: Session, before: datetime) -> int:
    res = session.execute(delete(IdempotencyRecord).where(IdempotencyRecord.created_at < before))
    return res.rowcount or 0
