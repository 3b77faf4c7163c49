"""A full refit in a child process of its own, under a memory limit.

A full refit (a promotion, a withdrawal from the known part) fits a new model on every
stored sample. With the worker embedded in an API process (the default), a fit in that
process shares its memory with recognition: at thousands of objects a fit takes gigabytes,
and running out of memory there stops recognition. So the fit runs in a spawned child (a
fork of a threaded server process is unsafe) that writes the model bundle to a temporary
file; the parent reads the child's resident memory every ``poll_seconds`` and kills it above
``memory_limit_bytes``. The old model answers meanwhile; a refit killed for memory raises
``RefitMemoryError``, which fails the retrain's jobs with that message and takes nothing
else down (the next enrolment that needs the refit tries again).
"""

from __future__ import annotations

import multiprocessing
import os
import tempfile
import traceback
from pathlib import Path
from typing import Any

from app.data.biotac import BioTacDataset
from app.data.dataset import TactileDataset
from app.framework import bundle
from app.framework.recognizer import TactileRecognizer


class RefitError(RuntimeError):
    """The refit's child process failed; the message says how."""


class RefitMemoryError(RefitError):
    """The refit's child process went over its memory limit and was stopped."""


def default_memory_limit() -> int:
    """Half of this machine's physical memory, in bytes."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2


def fit_in_child(
    method: str,
    params: dict[str, Any],
    dataset: TactileDataset | BioTacDataset,
    memory_limit_bytes: int,
    poll_seconds: float = 0.1,
) -> TactileRecognizer:
    """``make_method(method, **params).fit(dataset)`` in a child process, read back from
    its bundle; RefitMemoryError when the child's resident memory passed the limit,
    RefitError when it failed otherwise (with its exception's last line)."""
    context = multiprocessing.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="tactile-refit-") as tmp:
        out = Path(tmp) / "model.bundle"
        child = context.Process(
            target=_fit, args=(method, params, dataset, str(out)), name="tactile-refit"
        )
        child.start()
        peak = 0
        while child.is_alive():
            peak = max(peak, _resident_bytes(child.pid))
            if peak > memory_limit_bytes:
                child.kill()
                child.join()
                raise RefitMemoryError(
                    f"the refit of {len(dataset.class_names)} known classes went over its memory "
                    f"limit of {memory_limit_bytes / 2**20:.0f} MiB (TACTILE_REFIT_MEMORY_LIMIT_MB)"
                    " and was stopped; the active model stays"
                )
            child.join(poll_seconds)
        error = Path(tmp) / "error.txt"
        if child.exitcode != 0 or not out.is_file():
            why = (
                error.read_text().splitlines()[0]
                if error.is_file()
                else f"exit code {child.exitcode}"
            )
            raise RefitError(f"the refit's process failed: {why}")
        return bundle.load(out)


def _fit(method: str, params: dict[str, Any], dataset: Any, out: str) -> None:
    from app.framework.registry import make_method

    try:
        model = make_method(method, **params).fit(dataset)
        partial = Path(out + ".partial")
        partial.write_bytes(bundle.to_bytes(model))
        partial.rename(out)
    except BaseException as exc:  # the parent reads the reason; the exit code says it failed
        Path(out).with_name("error.txt").write_text(
            f"{type(exc).__name__}: {exc}\n" + traceback.format_exc(limit=-3)
        )
        raise SystemExit(1) from None


def _resident_bytes(pid: int | None) -> int:
    """The resident memory of process ``pid`` (0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, IndexError, ValueError):
        return 0
