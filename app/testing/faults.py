"""SQLite store faults for ``tests/reliability/test_sqlite_faults.py`` and
``scenarios.sqlite_faults``: a real full disk where this process may mount a small tmpfs,
and the DBAPI errors SQLite raises for a full disk or a read-only database, injected where
every statement goes through SQLAlchemy."""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from sqlalchemy import event

WRITES = ("INSERT", "UPDATE", "DELETE", "REPLACE")
MESSAGES = {
    "read-only": "attempt to write a readonly database",
    "disk full": "database or disk is full",
}


@contextlib.contextmanager
def tiny_filesystem(path: Path, megabytes: int) -> Iterator[bool]:
    """A tmpfs of ``megabytes`` at ``path``; yields False where none can be mounted."""
    path.mkdir(parents=True)
    mounted = False
    if sys.platform == "linux" and os.geteuid() == 0 and shutil.which("mount"):
        cmd = ["mount", "-t", "tmpfs", "-o", f"size={megabytes}m", "tmpfs", str(path)]
        mounted = subprocess.run(cmd, capture_output=True, check=False).returncode == 0
    try:
        yield mounted
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)


class Fault:
    """An injected SQLite write fault on an engine: with ``after_first``, the first write
    of each transaction goes through and the later ones fail (a disk that fills up in the
    middle of a transaction, so that a half-written one would show)."""

    def __init__(self, engine, message: str, after_first: bool) -> None:
        self.engine, self.message, self.after_first = engine, message, after_first
        self.on = False
        self.raised = 0
        event.listen(engine, "begin", self._begin)
        event.listen(engine, "before_cursor_execute", self._execute)

    def _begin(self, conn) -> None:
        conn.info["writes"] = 0

    def _execute(self, conn, _cursor, statement, *_args) -> None:
        if not self.on or not statement.lstrip().upper().startswith(WRITES):
            return
        conn.info["writes"] = conn.info.get("writes", 0) + 1
        if self.after_first and conn.info["writes"] == 1:
            return
        self.raised += 1
        raise sqlite3.OperationalError(self.message)

    def remove(self) -> None:
        event.remove(self.engine, "begin", self._begin)
        event.remove(self.engine, "before_cursor_execute", self._execute)


def fill(path: Path) -> Path:
    """Fill the filesystem of ``path`` to the last byte with one file; returns it."""
    filler = path / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    try:
        for size in (1 << 20, 4096, 1):  # then the last partial block
            with contextlib.suppress(OSError):
                while True:
                    os.write(fd, b"\0" * size)
    finally:
        os.close(fd)
    return filler
