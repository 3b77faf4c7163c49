"""Torch and BLAS threading for small models.

These networks and matrices are tiny: per-operator overhead dominates, and
intra-op threads mostly add contention with the API and other processes on a
2-core machine (measured under load: 20 ms per G+D step with 1 torch thread,
560 ms with 2; the best method's nearest-trial distances 0.6 ms per 32 samples
with 1 BLAS thread, 4 ms with 2). The default is therefore one thread for both;
TACTILE_TORCH_THREADS overrides it.

The process's entry point chooses, by calling ``configure_threads`` once at its start:
the ``train``, ``evaluate``, ``recognize`` and ``worker`` commands do, and every
``serve``, API and worker process through ``app.service.bootstrap.ensure_ready``
(with the ``torch_threads`` setting). Importing a method changes nothing. A process
that never chose still gets the default: fitting a recognizer or loading one from a
bundle calls ``ensure_threads_configured`` (and the paper's pipeline
``configure_torch``), so its first fit or answer already runs on one thread.

Torch is imported only by the methods that use it (the paper's pipeline): a process
that serves ``best`` never loads it, which saves a second and a few hundred MB.
"""

from __future__ import annotations

import os
import sys

from threadpoolctl import threadpool_limits

_threads: int | None = None  # what the process was configured with; None: not yet
_heap: bool | None = None  # whether configure_heap took; None: not called yet
_M_MMAP_THRESHOLD, _MMAP_FROM = -3, 1 << 20  # glibc's malloc.h: mallopt's parameter, 1 MiB


def configure_threads(threads: int | None = None) -> int:
    """The entry points' call: limit numpy's BLAS, and torch once it is loaded, to
    ``threads`` (default: TACTILE_TORCH_THREADS, else 1; 0 leaves the libraries' own
    defaults). Returns the number chosen; calling it again replaces the choice."""
    global _threads
    _threads = threads if threads is not None else int(os.environ.get("TACTILE_TORCH_THREADS", "1"))
    if _threads > 0:
        threadpool_limits(_threads, user_api="blas")  # numpy's BLAS, for the whole process
        # and faiss's OpenMP: unlimited, one sample's distances took 18.7 ms on 2 busy cores
        # against 0.23 ms on one thread (bench.grown_backlog --omp-threads)
        threadpool_limits(_threads, user_api="openmp")
        # and the libraries loaded later (numba's first compile loads scipy's BLAS)
        for name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ[name] = str(_threads)
        if "torch" in sys.modules:
            _set_torch_threads(_threads)
    return _threads


def ensure_threads_configured() -> None:
    """The default configuration, unless the process chose one already: what fitting
    and loading a recognizer call, for processes whose entry point did not."""
    if _threads is None:
        configure_threads()


def configure_heap() -> bool:
    """Arrays of 1 MiB and more get memory mappings of their own, given back to the
    system when freed (glibc's ``mallopt``; elsewhere nothing). glibc raises its mapping
    threshold as large blocks are freed, up to 32 MiB, so that a fit's arrays of a few MiB
    (a tree's nodes, a block of scores) then come from the heap, whose freed pages stay
    resident: the peak RSS of ``best``'s fit on 3,000 simulated objects was 1.57 GB with
    glibc's default and 1.44 GB with this (``bench.scale --sizes 3000``, 2026-11-27).
    Fitting a recognizer calls it; once a process has called it, later calls change
    nothing. Returns whether it took."""
    global _heap
    if _heap is None:
        import ctypes

        try:
            mallopt = ctypes.CDLL(None).mallopt  # the C library this process runs on
        except (OSError, TypeError, AttributeError):  # not glibc
            _heap = False
        else:
            _heap = bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_FROM))
    return _heap


def configure_torch() -> None:
    """For the methods that use torch, before they compute (fit, bundle loading): torch
    gets the process's threads, also when it was loaded after ``configure_threads``."""
    ensure_threads_configured()
    if _threads:
        _set_torch_threads(_threads)


def _set_torch_threads(n: int) -> None:
    import torch

    if torch.get_num_threads() != n:
        torch.set_num_threads(n)
