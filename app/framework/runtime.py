"""Torch threading for small models.

These networks are tiny: per-operator overhead dominates, and intra-op threads
mostly add contention with the API and other processes on a 2-core machine
(measured under load: 20 ms per G+D step with 1 thread, 560 ms with 2). The
default is therefore one thread; TACTILE_TORCH_THREADS overrides it.
"""

from __future__ import annotations

import os

import torch


def configure_torch_threads(threads: int | None = None) -> int:
    n = threads if threads is not None else int(os.environ.get("TACTILE_TORCH_THREADS", "1"))
    if n > 0 and torch.get_num_threads() != n:
        torch.set_num_threads(n)
    return torch.get_num_threads()


configure_torch_threads()
