"""Torch and BLAS threading for small models.

These networks and matrices are tiny: per-operator overhead dominates, and
intra-op threads mostly add contention with the API and other processes on a
2-core machine (measured under load: 20 ms per G+D step with 1 torch thread,
560 ms with 2; the best method's nearest-trial distances 0.6 ms per 32 samples
with 1 BLAS thread, 4 ms with 2). The default is therefore one thread for both;
TACTILE_TORCH_THREADS overrides it.
"""

from __future__ import annotations

import os

import torch
from threadpoolctl import threadpool_limits


def configure_torch_threads(threads: int | None = None) -> int:
    n = threads if threads is not None else int(os.environ.get("TACTILE_TORCH_THREADS", "1"))
    if n > 0 and torch.get_num_threads() != n:
        torch.set_num_threads(n)
    if n > 0:
        threadpool_limits(n, user_api="blas")  # numpy's BLAS, for the whole process
    return torch.get_num_threads()


configure_torch_threads()
