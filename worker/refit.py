"""A full refit in a child process of its own, under a memory limit the kernel enforces.

A full refit (a promotion, a withdrawal from the known part) fits a new model on every
stored sample. With the worker embedded in an API process (the default), a fit in that
process shares its memory with recognition: at thousands of objects a fit takes gigabytes,
and running out of memory there stops recognition. So the fit runs in a spawned child (a
fork of a threaded server process is unsafe) whose data segment the kernel caps at
``memory_limit_bytes`` (``RLIMIT_DATA``: an allocation past it fails at once, however
short the spike). ``RLIMIT_DATA``, not ``RLIMIT_AS``: torch, numba and the BLAS reserve
address space they never touch (after their imports a child's address space is 944 MB
where its resident memory is 279 MB and its data 252 MB; after a 60-object fit 1,332 MB,
445 MB and 498 MB), so an address-space cap would stop fits at a third of the memory it
names. The old model answers meanwhile; a refit stopped for memory raises
``RefitMemoryError``, which fails the retrain's jobs with that message and takes nothing
else down (the next enrolment that needs the refit tries again).

The parent holds no second copy of what it sends or gets back: the dataset is pickled to
a file, not into the pipe (``pickle.dumps`` of a 400 MB array peaks at 800 MB, a dump to
a file at 400 MB), and the child writes the model as a split bundle, a head and one file
per part, which the parent decodes one part at a time (``bundle.load`` of one file held
the file's bytes, its array archive's and the arrays at once).
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import pickle
import re
import resource
import signal
import tempfile
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from app.data.biotac import BioTacDataset
from app.data.dataset import TactileDataset
from app.framework import bundle
from app.framework.growing import gathered
from app.framework.recognizer import TactileRecognizer

#: where the kernel's cgroup files are mounted, and this process's cgroups
CGROUP_ROOT = Path("/sys/fs/cgroup")
PROC_CGROUP = Path("/proc/self/cgroup")
# cgroup v1 writes "no limit" as the largest page-aligned int64
_V1_UNLIMITED = 2**62


class RefitError(RuntimeError):
    """The refit's child process failed; the message says how."""


class RefitMemoryError(RefitError):
    """The refit's child process went over its memory limit and was stopped."""


def default_memory_limit(root: Path = CGROUP_ROOT, proc_cgroup: Path = PROC_CGROUP) -> int:
    """Half of the memory this process may use, in bytes: its container's (cgroup) memory
    limit where one is set, else the machine's physical memory. Half, since the API
    process, its model and recognition live within the same memory."""
    physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    limit = cgroup_memory_limit(root, proc_cgroup)
    return min(physical, limit or physical) // 2


def cgroup_memory_limit(root: Path = CGROUP_ROOT, proc_cgroup: Path = PROC_CGROUP) -> int | None:
    """The smallest memory limit set on this process's cgroup or any cgroup above it, in
    bytes (cgroup v2's ``memory.max``; v1's ``memory.limit_in_bytes`` on a host that
    mounts the memory controller the old way); None when none is set or readable."""
    try:
        lines = proc_cgroup.read_text().splitlines()
    except OSError:
        return None
    found: list[int] = []
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":  # v2: "0::/path"
            base, name = root, "memory.max"
        elif "memory" in controllers.split(","):
            base, name = root / "memory", "memory.limit_in_bytes"
        else:
            continue
        here = base / path.lstrip("/")
        while True:  # from this cgroup up to the root of the mount
            try:
                text = (here / name).read_text().strip()
            except OSError:
                text = ""
            if text.isdigit() and int(text) < _V1_UNLIMITED:
                found.append(int(text))
            if here == base or base not in here.parents:
                break
            here = here.parent
    return min(found) if found else None


def fit_in_child(
    method: str,
    params: dict[str, Any],
    dataset: TactileDataset | BioTacDataset,
    memory_limit_bytes: int,
) -> TactileRecognizer:
    """``make_method(method, **params).fit(dataset)`` in a child process whose data
    segment may not grow past ``memory_limit_bytes``, read back from its bundle;
    RefitMemoryError when it ran out of that memory, RefitError when it failed otherwise
    (with its exception's last line)."""
    context = multiprocessing.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="tactile-refit-") as tmp:
        folder = Path(tmp)
        with open(folder / "dataset.pickle", "wb") as f:  # written as it goes: no copy here
            pickle.dump(dataset, f, protocol=pickle.HIGHEST_PROTOCOL)
        child = context.Process(
            target=_fit, args=(method, params, tmp, memory_limit_bytes), name="tactile-refit"
        )
        child.start()
        child.join()
        error = folder / "error.txt"
        head = folder / "model" / "head"
        if child.exitcode == 0 and head.is_file():
            return _load_split(folder / "model")
        if error.is_file():
            kind, why = error.read_text().split("\n", 1)[0].split(" ", 1)
        else:  # ended by a library or a signal: its last words, if any
            stderr = folder / "stderr.txt"
            said = (
                stderr.read_text(errors="replace").strip().splitlines() if stderr.is_file() else []
            )
            why = said[-1] if said else f"exit code {child.exitcode}"
            kind = "memory" if _MEMORY_WORDS.search(why) else "error"
        if kind == "memory" or child.exitcode == -signal.SIGKILL:
            raise RefitMemoryError(
                f"the refit of {len(dataset.class_names)} known classes went over its memory "
                f"limit of {memory_limit_bytes / 2**20:.0f} MiB (TACTILE_REFIT_MEMORY_LIMIT_MB)"
                f" and was stopped ({why}); the active model stays"
            )
        raise RefitError(f"the refit's process failed: {why}")


def _fit(method: str, params: dict[str, Any], folder: str, memory_limit_bytes: int) -> None:
    resource.setrlimit(resource.RLIMIT_DATA, (memory_limit_bytes, memory_limit_bytes))
    out = Path(folder)
    # what a library prints before it exits without a Python exception (OpenBLAS: "Memory
    # allocation still failed after 10 retries, giving up.") stays for the parent to read
    with open(out / "stderr.txt", "wb") as err:
        os.dup2(err.fileno(), 2)
    try:
        from app.framework.registry import make_method

        with open(out / "dataset.pickle", "rb") as f:
            dataset = pickle.load(f)
        model = make_method(method, **params).fit(dataset)
        del dataset
        head, parts = bundle.split(model)
        partial = out / "model.partial"
        partial.mkdir()
        for sha, blob in parts.items():
            (partial / sha).write_bytes(blob)
        (partial / "head").write_bytes(head)
        partial.rename(out / "model")
    except BaseException as exc:  # the parent reads the reason; the exit code says it failed
        kind = "memory" if _out_of_memory(exc) else "error"
        (out / "error.txt").write_text(
            f"{kind} {type(exc).__name__}: {exc}\n" + traceback.format_exc(limit=-3)
        )
        raise SystemExit(1) from None


#: how libraries say an allocation was refused (torch's CPU allocator, OpenBLAS, C's
#: errno, the dynamic loader mapping a library under a limit its imports do not fit in)
_MEMORY_WORDS = re.compile(
    r"can't allocate memory|memory allocation|cannot allocate memory|out of memory"
    r"|cannot map zero-fill pages|failed to map segment",
    re.I,
)


def _out_of_memory(exc: BaseException) -> bool:
    """An allocation refused: Python's and numpy's MemoryError, numba's, and torch's
    RuntimeError from its CPU allocator."""
    return isinstance(exc, MemoryError) or bool(_MEMORY_WORDS.search(str(exc)))


def _load_split(folder: Path) -> TactileRecognizer:
    """The model of a split bundle written as files, decoding one part at a time, and
    gathering an array stored in row blocks straight into one array."""

    def part(sha: str) -> np.ndarray:
        return bundle.decode_part((folder / sha).read_bytes())

    def join(shas: list[str]) -> np.ndarray:
        first = part(shas[0])
        rest = (part(sha) for sha in shas[1:])
        return gathered(itertools.chain([first], rest), len(first) * len(shas))

    return bundle.from_bytes((folder / "head").read_bytes(), part=part, join=join)
