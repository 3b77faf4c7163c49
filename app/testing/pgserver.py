"""A throwaway PostgreSQL server of its own (initdb + pg_ctl on a free port, its data under a
temporary folder) that a scenario may stop, crash and restart: the shared server on 5432
is never touched.

Run as root, the server's commands run as the ``postgres`` user (initdb refuses root).
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from app.testing.harness import free_port

STOP_MODES = ("fast", "immediate", "kill")  # pg_ctl -m fast / -m immediate / SIGKILL postmaster


def find_bindir() -> Path | None:
    """The folder holding initdb and pg_ctl: $PG_BINDIR, the newest
    /usr/lib/postgresql/*/bin, or the PATH."""
    candidates = [os.environ.get("PG_BINDIR", "")]
    candidates += sorted(
        glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(p.split("/")[-2]), reverse=True
    )
    which = shutil.which("pg_ctl")
    if which:
        candidates.append(str(Path(which).resolve().parent))
    for c in candidates:
        if c and (Path(c) / "initdb").exists() and (Path(c) / "pg_ctl").exists():
            return Path(c)
    return None


def missing_reason() -> str | None:
    """Why no throwaway server can be made here; None when one can."""
    if find_bindir() is None:
        return "no PostgreSQL server binaries (initdb, pg_ctl) found: set PG_BINDIR"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            return "running as root and there is no 'postgres' user to run initdb as"
        if shutil.which("runuser") is None:
            return "running as root without runuser to run initdb as 'postgres'"
    return None


class PostgresServer:
    """``start()``, ``stop(mode)`` with mode in STOP_MODES, ``url``; ``close()`` removes it."""

    def __init__(self) -> None:
        bindir = find_bindir()
        if bindir is None:
            raise RuntimeError(missing_reason())
        self.bindir = bindir
        self.port = free_port()
        # not under pytest's tmp_path: its folders are 0700 to root, and the server runs as
        # 'postgres' when the test runs as root
        self.root = Path(tempfile.mkdtemp(prefix="tactile-pg-"))
        self.data = self.root / "data"
        self.log = self.root / "server.log"
        self.as_user: list[str] = []
        self.postmaster: subprocess.Popen | None = None
        if os.geteuid() == 0:
            user = pwd.getpwnam("postgres")
            os.chown(self.root, user.pw_uid, user.pw_gid)
            # setpriv execs (no process in between), so the postmaster is our child: a
            # SIGKILLed one is reaped here and leaves no zombie holding postmaster.pid
            self.as_user = ["setpriv", "--reuid=postgres", "--regid=postgres", "--init-groups"]
        self._run(
            "initdb",
            "-D",
            str(self.data),
            "-U",
            "postgres",
            "--auth=trust",
            "-E",
            "UTF8",
            "--no-sync",
        )
        with open(self.data / "postgresql.conf", "a") as conf:
            conf.write(
                f"\nport = {self.port}\nlisten_addresses = '127.0.0.1'\n"
                f"unix_socket_directories = '{self.root}'\n"
                "max_connections = 100\nshared_buffers = 32MB\n"
                # a process killed, not the machine: what was committed is in the OS's page
                # cache either way, so syncing it to disk would only slow the run down
                "fsync = off\nfull_page_writes = off\n"
                "log_min_messages = warning\n"
            )
        self.url = f"postgresql://postgres@127.0.0.1:{self.port}/postgres"

    def _run(self, tool: str, *args: str, timeout: float = 120) -> None:
        subprocess.run(
            [*self.as_user, str(self.bindir / tool), *args],
            check=True,
            capture_output=True,
            timeout=timeout,
        )

    def postmaster_pid(self) -> int | None:
        try:
            return int((self.data / "postmaster.pid").read_text().split()[0])
        except (FileNotFoundError, ValueError, IndexError):
            return None

    def start(self, timeout: float = 120) -> None:
        """Start the postmaster (as this process's child) and wait until it accepts
        connections (crash recovery included)."""
        log = open(self.log, "ab")  # noqa: SIM115 - the server's for as long as it runs
        self.postmaster = subprocess.Popen(
            [*self.as_user, str(self.bindir / "postgres"), "-D", str(self.data)],
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        log.close()
        deadline = time.monotonic() + timeout
        ready = [str(self.bindir / "pg_isready"), "-q", "-h", "127.0.0.1", "-p", str(self.port)]
        ready += ["-U", "postgres"]
        while subprocess.run([*ready, "-t", "1"], check=False).returncode != 0:
            if self.postmaster.poll() is not None:
                raise RuntimeError(f"PostgreSQL did not start:\n{self.logs()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"PostgreSQL not ready after {timeout}s:\n{self.logs()}")
            time.sleep(0.05)

    def stop(self, mode: str) -> None:
        """``fast`` and ``immediate``: pg_ctl's shutdown modes (immediate skips the
        checkpoint, so the next start runs crash recovery); ``kill``: SIGKILL to the
        postmaster, then its orphaned backends are waited for (they notice the postmaster's
        death and exit) and killed after 10 s, as a service manager would."""
        if mode in ("fast", "immediate"):
            self._run("pg_ctl", "-D", str(self.data), "-m", mode, "-w", "-t", "60", "stop")
            self._reap()
            return
        if mode != "kill":
            raise ValueError(f"unknown stop mode {mode!r}")
        pid = self.postmaster_pid()
        if pid is None:
            return
        children = _children(pid)
        os.kill(pid, signal.SIGKILL)
        self._reap()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if not _alive(pid) and not any(_alive(c) for c in children):
                return
            time.sleep(0.05)
        for c in children:
            if _alive(c):
                os.kill(c, signal.SIGKILL)

    def _reap(self) -> None:
        if self.postmaster is not None:
            self.postmaster.wait(30)
            self.postmaster = None

    def close(self) -> None:
        if self.postmaster_pid() is not None and _alive(self.postmaster_pid()):
            try:
                self.stop("immediate")
            except subprocess.SubprocessError:
                self.stop("kill")
        shutil.rmtree(self.root, ignore_errors=True)

    def logs(self, tail: int = 3000) -> str:
        try:
            return self.log.read_text(errors="replace")[-tail:]
        except FileNotFoundError:
            return ""


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has exited


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out
