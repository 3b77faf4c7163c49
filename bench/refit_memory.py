"""What a full refit's parent holds beside the child (worker/refit.py): the peak memory of
sending the dataset (pickled into memory, as the pipe to a spawned child took it, or to a
file) and of reading the fitted model back (``bundle.load`` of one file, or the split
bundle's head and parts one at a time). Each is measured in a fresh interpreter, from its
resident memory before to its high-water mark (``VmHWM``) after.

    python -m bench.refit_memory --objects 300 --out docs/results/refit_memory/refit_memory.json
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.scale import machine

MEASURE = """
import pickle, sys
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
from app.framework import bundle
from worker import refit
folder = sys.argv[2]
{setup}
before = status("VmRSS")
{step}
print(before, status("VmHWM"))
"""

STEPS = {
    "dataset_pickled_in_memory": (
        "data = pickle.load(open(folder + '/dataset.pickle', 'rb'))",
        "blob = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)",
    ),
    "dataset_pickled_to_a_file": (
        "data = pickle.load(open(folder + '/dataset.pickle', 'rb'))",
        "pickle.dump(data, open(folder + '/again.pickle', 'wb'), protocol=pickle.HIGHEST_PROTOCOL)",
    ),
    "model_from_one_bundle_file": ("", "model = bundle.load(folder + '/model.bundle')"),
    "model_from_split_files": (
        "",
        "from pathlib import Path; m = Path(folder) / 'model'; "
        "model = refit._read_split(m / 'head', m, {})",
    ),
}


def measure(folder: Path, name: str) -> dict:
    setup, step = STEPS[name]
    code = MEASURE.format(setup=setup, step=step)
    out = subprocess.run(
        [sys.executable, "-c", code, name, str(folder)], capture_output=True, text=True, check=True
    )
    before, peak = (int(v) for v in out.stdout.split()[-2:])
    return {"before_mb": round(before / 1e6, 1), "peak_mb": round(peak / 1e6, 1)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--objects", type=int, default=300, help="simulated objects (10 trials each)")
    p.add_argument("--out", type=Path, required=True, help="JSON file to write")
    args = p.parse_args(argv)
    if args.objects < 2:
        p.error("--objects must be at least 2")

    import pickle

    from app.data.simulator import simulate_dataset
    from app.framework import bundle
    from app.framework.registry import make_method

    dataset = simulate_dataset(args.objects, 10, seed=0)
    started = time.perf_counter()
    model = make_method("best", seed=0).fit(dataset)
    fit_seconds = time.perf_counter() - started
    with tempfile.TemporaryDirectory(prefix="refit-memory-") as tmp:
        folder = Path(tmp)
        with open(folder / "dataset.pickle", "wb") as f:
            pickle.dump(dataset, f, protocol=pickle.HIGHEST_PROTOCOL)
        bundle.save(model, folder / "model.bundle")
        head, parts = bundle.split(model)
        (folder / "model").mkdir()
        for sha, blob in parts.items():
            (folder / "model" / sha).write_bytes(blob)
        (folder / "model" / "head").write_bytes(head)
        sizes = {
            "dataset_samples_mb": round(dataset.samples.nbytes / 1e6, 1),
            "bundle_file_mb": round((folder / "model.bundle").stat().st_size / 1e6, 1),
        }
        results = {name: measure(folder, name) for name in STEPS}
    for r in results.values():
        r["added_mb"] = round(r["peak_mb"] - r["before_mb"], 1)
    report = {
        "what": "peak memory a refit's parent adds to send the dataset and read the model back",
        "command": "python -m bench.refit_memory " + " ".join(argv or sys.argv[1:]),
        "objects": args.objects,
        "fit_seconds": round(fit_seconds, 1),
        **sizes,
        "results": results,
        "machine": machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
