"""What a model holds in an API process's memory: the active version of a store, loaded in
this fresh process as the model holder loads it (``bundles.load_model`` through a
``PartCache``), then one sample recognised.

    .venv/bin/python -m bench.model_memory --data-dir DIR

``DIR`` is a service's data folder (``tactile-zsl serve --data-dir``; ``bench.scale_service
--keep`` keeps one). Printed: resident memory after the load and after the recognition,
the peak (Linux's ``VmRSS`` / ``VmHWM``), the bytes of the model's arrays (what its bundle
holds, decoded), of its forests' node records among them, and of the leaf-redirect buffers
its forests hold (none until a promotion grows a forest: ``app.methods.forest._Redirects``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from app.config import Settings
from app.framework import bundle
from app.methods.forest import FlatForest
from app.store import bundles, repo
from app.store.db import make_engine, make_sessionmaker


def memory_gb() -> dict[str, float]:
    """``VmRSS`` and ``VmHWM`` of this process, in GB."""
    out = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key] = int(value.split()[0]) * 1024 / 1e9
    return out


def forests(obj, seen: set[int] | None = None):
    """The ``FlatForest``s reachable from ``obj``'s attributes, each once."""
    seen = set() if seen is None else seen
    if id(obj) in seen or isinstance(obj, (np.ndarray, str, bytes, int, float)):
        return
    seen.add(id(obj))
    if isinstance(obj, FlatForest):
        yield obj
        return
    values = obj.values() if isinstance(obj, dict) else obj if isinstance(obj, list) else None
    if values is None:
        values = vars(obj).values() if hasattr(obj, "__dict__") else ()
    for value in values:
        yield from forests(value, seen)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data-dir", type=Path, required=True, help="a service's data folder")
    args = p.parse_args(argv)
    url = Settings(data_dir=args.data_dir).sqlalchemy_url
    sessions = make_sessionmaker(make_engine(url))
    t = time.perf_counter()
    with sessions() as s:
        version = repo.active_version(s)
        if version is None:
            p.exit(2, f"model_memory: {args.data_dir} holds no active model version\n")
        model = bundles.load_model(s, version.bundle_sha256, bundles.PartCache())
    load_s = time.perf_counter() - t
    loaded = memory_gb()
    model.recognize(np.zeros((1, *model.input_shape), np.float32))
    answered = memory_gb()
    _, arrays = bundle._contents(model)
    array_mb = sum(a.nbytes for a in arrays.values() if isinstance(a, np.ndarray)) / 1e6
    found = list(forests(model))
    records_mb = sum(f.nodes.nbytes for f in found) / 1e6
    redirects_mb = sum(f.redirect_nbytes for f in found) / 1e6
    print(f"model version {version.version} ({len(model.registry.known_names)} known classes)")
    rss, peak = answered["VmRSS"], answered["VmHWM"]
    print(f"load: {load_s:.1f} s; resident {loaded['VmRSS']:.2f} GB after it, {rss:.2f} GB")
    print(f"after one recognition, peak {peak:.2f} GB")
    print(f"model arrays {array_mb:.3f} MB, of which forest node records {records_mb:.3f} MB")
    print(f"forest leaf redirects (made by promotions) {redirects_mb:.3f} MB")


if __name__ == "__main__":
    main()
