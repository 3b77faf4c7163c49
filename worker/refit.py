"""A full refit in a child process of its own, under memory and time limits.

A full refit (a promotion, a withdrawal from the known part) fits a new model on every
stored sample, and so does an attribute rebuild (``with_attributes``: the vocabulary or a
known class's values changed) for the parts that learn attributes. With the worker
embedded in an API process (the default), a fit in that process shares its memory with
recognition: at thousands of objects a fit takes gigabytes, and running out of memory there
stops recognition. So the fit runs in a spawned child (a fork of a threaded server process
is unsafe) whose data segment the kernel caps at ``memory_limit_bytes`` (``RLIMIT_DATA``:
an allocation past it fails at once, however short the spike). ``RLIMIT_DATA``, not
``RLIMIT_AS``: torch, numba and the BLAS reserve address space they never touch (after
their imports a child's address space is 944 MB where its resident memory is 279 MB and its
data 252 MB; after a 60-object fit 1,332 MB, 445 MB and 498 MB), so an address-space cap
would stop fits at a third of the memory it names. The old model answers meanwhile; a
refit stopped for memory raises ``RefitMemoryError``, which fails the retrain's jobs with
that message and takes nothing else down (the next enrolment that needs the refit tries
again). A refused allocation is a memory stop however a library reports it: Python's and
numpy's MemoryError, torch's allocator error, faiss's C++ ``std::bad_alloc`` (a MemoryError
through its bindings, its own error naming it, or an abort printing it), a library's
message on stderr, or the child killed by SIGKILL, as the kernel's out-of-memory killer
does.

The child leads a process group of its own and may run ``seconds`` of wall clock: past
them the parent kills the group (the child and whatever it started) and raises
``RefitTimeoutError``, with the same effect on the jobs. A parent that waited without a
limit kept the worker's round, and every job behind it, waiting on a fit that never ends.

The parent holds no second copy of what it sends or gets back: the dataset is pickled to
a file, not into the pipe (``pickle.dumps`` of a 400 MB array peaks at 800 MB, a dump to
a file at 400 MB); the base model of an attribute rebuild is written as a split bundle one
row block at a time; and the child writes the model as a split bundle, a head and one file
per part, which the parent decodes one part at a time (``bundle.load`` of one file held
the file's bytes, its array archive's and the arrays at once), taking the base model's own
array where a part is byte for byte one of its own.
"""

from __future__ import annotations

import ctypes
import faulthandler
import hashlib
import itertools
import multiprocessing
import os
import pickle
import re
import resource
import signal
import tempfile
import traceback
from collections.abc import Callable
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
PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent ends
# cgroup v1 writes "no limit" as the largest page-aligned int64
_V1_UNLIMITED = 2**62


class RefitError(RuntimeError):
    """The refit's child process failed; the message says how."""


class RefitMemoryError(RefitError):
    """The refit's child process went over its memory limit and was stopped."""


class RefitTimeoutError(RefitError):
    """The refit's child process ran past its wall-clock limit and was killed."""


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
    seconds: float = 0.0,
) -> TactileRecognizer:
    """``make_method(method, **params).fit(dataset)`` in a child process whose data
    segment may not grow past ``memory_limit_bytes`` and which may run ``seconds`` of wall
    clock (0: no limit), read back from its bundle; RefitMemoryError when it ran out of that
    memory, RefitTimeoutError when it ran out of time, RefitError when it failed otherwise
    (with its exception's last line)."""
    what = f"the refit of {len(dataset.class_names)} known classes"
    return run_in_child(_fit, (method, params), dataset, memory_limit_bytes, seconds, what=what)


def attributes_in_child(
    model: TactileRecognizer,
    dataset: TactileDataset | BioTacDataset,
    memory_limit_bytes: int,
    seconds: float = 0.0,
) -> TactileRecognizer:
    """``model.with_attributes(dataset)`` in a child process under the same limits as
    ``fit_in_child``, and with its errors. ``model`` goes to the child as a split bundle
    written one row block at a time; the new model's arrays that are byte for byte
    ``model``'s (everything but the attribute parts) come back as ``model``'s own arrays, not
    as copies, as an attribute rebuild in this process would share them."""
    what = f"the attribute refit of {len(dataset.class_names)} known classes"
    return run_in_child(_with_attributes, (), dataset, memory_limit_bytes, seconds, what, model)


def run_in_child(
    task: Callable[..., TactileRecognizer],
    args: tuple,
    dataset: TactileDataset | BioTacDataset,
    memory_limit_bytes: int,
    seconds: float = 0.0,
    what: str = "the refit",
    base: TactileRecognizer | None = None,
) -> TactileRecognizer:
    """``task(dataset, base, *args)`` (a module-level function, which the spawned child
    imports) in a child process of its own process group, whose data segment may not grow
    past ``memory_limit_bytes``, killed with its group after ``seconds`` (0: never); the
    model it returns, read back. ``what`` names the work in error messages. ``base``: a
    model the child reads from a split bundle, whose arrays the returned model shares
    where they are unchanged."""
    context = multiprocessing.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="tactile-refit-") as tmp:
        folder = Path(tmp)
        (folder / "parts").mkdir()
        with open(folder / "dataset.pickle", "wb") as f:  # written as it goes: no copy here
            pickle.dump(dataset, f, protocol=pickle.HIGHEST_PROTOCOL)
        mine: dict[Any, np.ndarray] = {}  # the base's arrays by part
        if base is not None:
            (folder / "base").write_bytes(_write_split(base, folder / "parts", mine))
        child = context.Process(
            target=_child,
            args=(task, args, tmp, memory_limit_bytes),
            name="tactile-refit",
        )
        child.start()
        try:
            child.join(seconds if seconds > 0 else None)
            timed_out = child.exitcode is None
        finally:  # past its time, or this thread interrupted: the child and its own children
            _kill_group(child)
            child.join()
        if timed_out:
            raise RefitTimeoutError(
                f"{what} ran past its time limit of {_duration(seconds)} "
                f"(TACTILE_REFIT_SECONDS) and was stopped; the active model stays. Raise "
                "TACTILE_REFIT_SECONDS (0: no limit) to let it finish"
            )
        if child.exitcode == 0 and (folder / "model").is_file():
            return _read_split(folder / "model", folder / "parts", mine)
        kind, why = _failure(folder, child.exitcode)
        if kind == "memory":
            raise RefitMemoryError(
                f"{what} went over its memory limit of {memory_limit_bytes / 2**20:.0f} MiB "
                f"(TACTILE_REFIT_MEMORY_LIMIT_MB) and was stopped ({why}); the active model "
                "stays. Raise TACTILE_REFIT_MEMORY_LIMIT_MB to give it more"
            )
        raise RefitError(f"the refit's process failed: {why}")


def _kill_group(child: multiprocessing.process.BaseProcess) -> None:
    """SIGKILL to the child's process group (it leads one from its first statement: what
    it started dies with it), and to the child itself, which may not lead it yet."""
    if child.pid is None:
        return
    try:
        os.killpg(child.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass  # no group by that id: the child has not made it yet, or it is gone
    if child.exitcode is None:
        child.kill()


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:g} h ({seconds:g} s)"
    return f"{seconds:g} s"


def _failure(folder: Path, exitcode: int | None) -> tuple[str, str]:
    """("memory" or "error", why) of a child that ended without a model: its own report,
    else what a library printed before it ended the process, else how it ended."""
    error = folder / "error.txt"
    if error.is_file():
        kind, why = error.read_text().split("\n", 1)[0].split(" ", 1)
        return kind, why
    stderr = folder / "stderr.txt"
    said = stderr.read_text(errors="replace").splitlines()[-200:] if stderr.is_file() else []
    said = [line.strip() for line in said if line.strip()]
    how = f"exit code {exitcode}"
    if exitcode is not None and exitcode < 0:
        how = f"ended by {signal.Signals(-exitcode).name}"
    # a C++ library's std::bad_alloc thrown where nothing catches it (faiss in a parallel
    # region) aborts with "terminate called after throwing an instance of 'std::bad_alloc'";
    # OpenBLAS prints "Memory allocation still failed after 10 retries, giving up."
    # (faulthandler's stack lines name functions, not what a library said)
    memory = [line for line in said if _MEMORY_WORDS.search(line) and not line.startswith("File")]
    if memory:
        return "memory", f"{memory[0]}; {how}"
    if exitcode == -signal.SIGKILL:
        # not ours (a timeout is told apart before): the kernel's out-of-memory killer
        return "memory", f"{how}, as the kernel's out-of-memory killer ends a process"
    fatal = [line for line in said if line.startswith("Fatal Python error")]
    last = fatal[-1] if fatal else (said[-1] if said else "")
    return "error", f"{last}; {how}" if last else how


def _die_with_parent() -> None:
    """Ask Linux for SIGKILL when the thread that started this child ends: an API process
    stopped (or killed) mid-refit cannot kill its group, and the refit would go on alone
    for up to TACTILE_REFIT_SECONDS, its result read by nobody."""
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the parent's own kill is all there is
        return
    if os.getppid() != parent:  # it died before we asked
        os._exit(1)


def _child(
    task: Callable[..., TactileRecognizer],
    args: tuple,
    folder: str,
    memory_limit_bytes: int,
) -> None:
    os.setpgid(0, 0)  # a group of its own, which a timeout kills whole
    _die_with_parent()
    # the libraries a fit loads, before the limit: they count against it all the same (their
    # memory is data already), but faiss's library crashed while it loaded under a limit it
    # did not fit in (SIGSEGV, at 500 MiB), where an allocation refused later is an error
    import faiss  # noqa: F401

    import app.framework.registry  # noqa: F401

    resource.setrlimit(resource.RLIMIT_DATA, (memory_limit_bytes, memory_limit_bytes))
    out = Path(folder)
    # what a library prints before it exits without a Python exception (OpenBLAS: "Memory
    # allocation still failed after 10 retries, giving up.") stays for the parent to read,
    # and so does the Python stack of a crash (faulthandler)
    with open(out / "stderr.txt", "wb") as err:
        os.dup2(err.fileno(), 2)
    faulthandler.enable()
    try:
        with open(out / "dataset.pickle", "rb") as f:
            dataset = pickle.load(f)
        base = None
        if (out / "base").is_file():
            base = _read_split(out / "base", out / "parts", {}, freeze=True)
        model = task(dataset, base, *args)
        del dataset, base
        head = _write_split(model, out / "parts", None)
        (out / "model.partial").write_bytes(head)
        (out / "model.partial").rename(out / "model")
    except BaseException as exc:  # the parent reads the reason; the exit code says it failed
        kind = "memory" if _out_of_memory(exc) else "error"
        said = str(exc).strip()
        if not said:  # numpy's MemoryError from deep inside may say nothing: say where
            frames = [
                f for f in traceback.extract_tb(exc.__traceback__) if "<frozen" not in f.filename
            ]
            said = f"in {frames[-1].filename}:{frames[-1].lineno}" if frames else ""
        (out / "error.txt").write_text(
            f"{kind} {type(exc).__name__}: {said}\n" + traceback.format_exc(limit=-3)
        )
        raise SystemExit(1) from None


def _fit(
    dataset: TactileDataset | BioTacDataset,
    base: TactileRecognizer | None,
    method: str,
    params: dict[str, Any],
) -> TactileRecognizer:
    from app.framework.registry import make_method

    return make_method(method, **params).fit(dataset)


def _with_attributes(
    dataset: TactileDataset | BioTacDataset, base: TactileRecognizer | None
) -> TactileRecognizer:
    return base.with_attributes(dataset)


#: how libraries say an allocation was refused (torch's CPU allocator, OpenBLAS, C's
#: errno, the dynamic loader mapping a library under a limit its imports do not fit in,
#: C++'s std::bad_alloc, which faiss raises as MemoryError or wraps in its own error), and
#: the last line of Python's traceback of a MemoryError that escaped before the child's own
#: report was written (under a limit below what its imports hold, writing it needs memory)
_MEMORY_WORDS = re.compile(
    r"can't allocate memory|memory allocation|cannot allocate memory|out of memory"
    r"|cannot map zero-fill pages|failed to map segment|bad_alloc|^MemoryError\b",
    re.I,
)


def _out_of_memory(exc: BaseException) -> bool:
    """An allocation refused: Python's and numpy's MemoryError (faiss's std::bad_alloc
    among them), numba's, torch's RuntimeError from its CPU allocator, and an error whose
    message names std::bad_alloc (faiss's, from a parallel region)."""
    return isinstance(exc, MemoryError) or bool(_MEMORY_WORDS.search(str(exc)))


def _write_split(
    model: TactileRecognizer, parts: Path, mine: dict[Any, np.ndarray] | None
) -> bytes:
    """``model`` as a split bundle's head, its parts written into ``parts`` one row block
    at a time (``bundle.split`` would hold every part's bytes at once) as ``.npy`` files
    named by their SHA-256; a part already there is not written again. ``mine``, where
    given, gets each part's array or row block of ``model`` by its SHA-256, and each array
    stored in row blocks by the tuple of theirs (what ``_read_split`` shares)."""
    manifest, arrays = bundle._contents(model)
    refs: dict[str, str | list[str]] = {}
    for name in [n for n, a in arrays.items() if np.asanyarray(a).nbytes >= bundle.PART_MIN_BYTES]:
        shas = []
        array = np.asanyarray(arrays.pop(name))
        for block in bundle.row_blocks(array):
            data = bundle._npy(block)
            sha = hashlib.sha256(data).hexdigest()
            if not (parts / sha).is_file():
                (parts / sha).write_bytes(data)
            if mine is not None:
                mine[sha] = block
            shas.append(sha)
            del data
        if mine is not None and len(shas) > 1:
            mine[tuple(shas)] = array
        refs[name] = shas[0] if len(shas) == 1 else shas
    manifest["parts"] = refs
    if any(isinstance(ref, list) for ref in refs.values()):
        manifest["format_version"] = max(manifest["format_version"], bundle.GROWN_FORMAT_VERSION)
    return bundle._zip(manifest, arrays)


def _read_split(
    head: Path, parts: Path, mine: dict[Any, np.ndarray], freeze: bool = False
) -> TactileRecognizer:
    """The model of a split bundle written as files (``_write_split``), decoding one part at
    a time, and gathering an array stored in row blocks straight into one array. A part, or
    a list of row blocks, in ``mine`` is the array found there, not a copy. ``freeze``: the arrays
    read-only (``bundle.unchangeable``), so that a model derived from this one shares them
    instead of copying them."""

    def part(sha: str) -> np.ndarray:
        if sha in mine:
            return mine[sha]
        array = bundle.decode_part((parts / sha).read_bytes())
        if freeze:
            bundle.freeze(array)
        return array

    def join(shas: list[str]) -> np.ndarray:
        if tuple(shas) in mine:
            return mine[tuple(shas)]
        first = part(shas[0])
        rest = (part(sha) for sha in shas[1:])
        return gathered(itertools.chain([first], rest), len(first) * len(shas))

    return bundle.from_bytes(head.read_bytes(), part=part, join=join)
