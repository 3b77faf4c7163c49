"""The API keys an API process accepts, and a per-key rate limit.

Keys live in the store (SHA-256 only) and are re-read by a background thread
every ``api_key_refresh_seconds``, so the request path never waits on the
database: a presented key is hashed, found by its hash, and the hashes are
compared with ``hmac.compare_digest``. Keys from ``TACTILE_API_KEYS`` count as
admin keys. Once any key exists (revoked ones included: revoking the last key
must not open the service), every ``/v1`` request needs one.
"""

from __future__ import annotations

import hmac
import logging
import math
import threading
import time
from dataclasses import dataclass

from sqlalchemy.orm import Session, sessionmaker

from app.service.polling import Poller
from app.store import repo

log = logging.getLogger(__name__)

RANK = {scope: i for i, scope in enumerate(repo.SCOPES)}


@dataclass(frozen=True)
class Principal:
    """Who sent a request: ``id`` keys rate limits and idempotency records."""

    id: str
    scope: str

    def allows(self, scope: str) -> bool:
        return RANK[self.scope] >= RANK[scope]


class KeyRing(Poller):
    _thread_name = "api-keys"
    _failure = "could not read the API keys"

    def __init__(
        self, sessions: sessionmaker[Session], env_keys: list[str], poll_seconds: float = 1.0
    ) -> None:
        super().__init__(poll_seconds)
        self._sessions = sessions
        self._env_keys = env_keys  # the settings' list: read at each refresh
        self._table: dict[str, tuple[str, str, str]] = {}  # sha256 -> (principal, scope, sha256)
        self._required = False

    @property
    def required(self) -> bool:
        return self._required

    def refresh(self) -> None:
        with self._sessions() as s:
            any_stored, stored = repo.api_key_table(s)
        table = {sha: (f"key:{key_id}", scope, sha) for sha, (key_id, scope) in stored.items()}
        for key in self._env_keys:
            sha = repo.hash_key(key)
            table[sha] = (f"env:{sha[:16]}", "admin", sha)
        self._table, self._required = table, any_stored or bool(self._env_keys)

    def set_env_keys(self, keys: list[str]) -> None:
        self._env_keys = keys
        self.refresh()

    def authenticate(self, key: str) -> Principal | None:
        sha = repo.hash_key(key)
        # found by its hash, then the hashes compared in constant time
        entry = self._table.get(sha)
        if entry is None or not hmac.compare_digest(entry[2].encode(), sha.encode()):
            return None
        return Principal(entry[0], entry[1])


class RateLimiter:
    """A token bucket per principal, in this process (``rate`` 0 = unlimited)."""

    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, burst
        self._buckets: dict[str, tuple[float, float]] = {}  # id -> (tokens, last refill)
        self._lock = threading.Lock()

    def acquire(self, principal: str) -> float:
        """0 when the request may go ahead, else the seconds to wait."""
        if self.rate <= 0:
            return 0.0
        now = time.monotonic()
        with self._lock:
            tokens, last = self._buckets.get(principal, (float(self.burst), now))
            tokens = min(float(self.burst), tokens + (now - last) * self.rate)
            if tokens >= 1.0:
                self._buckets[principal] = (tokens - 1.0, now)
                return 0.0
            self._buckets[principal] = (tokens, now)
            return (1.0 - tokens) / self.rate


def retry_after(seconds: float) -> str:
    return str(max(1, math.ceil(seconds)))
