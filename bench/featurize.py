"""What one raw BioTac trial costs on its way to an answer, step by step, in one process.

    .venv/bin/python -m bench.featurize [--data ../shared/data/biotac_pilot] [--repeats 5]

On the real pilot recordings (74 trials, ~4,100–11,100 frames, two fingers each): a model
(``best``) is fitted on every trial, then each trial's JSON body is parsed (orjson) and
validated (``parse_trial``), as is the same trial sent as HDF5, featurized into the
paper's tactile images (``TactileImageFeaturizer.transform``, one image per finger) and
recognised from both fingers (``recognize_batch`` with groups); the store's encoding of a
trial (``.npz``) is timed too. Printed: the median per trial of each step and its share of
the whole, so the figures compare across machines as ratios; absolute times are this
machine's only.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import orjson

from app.data.biotac import parse_trial, read_biotac_h5, write_biotac_h5
from app.data.sources import open_dataset
from app.framework.registry import make_method
from app.framework.runtime import configure_threads
from app.store.repo import encode_trial

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "biotac_pilot"


def hdf5_body(trial) -> bytes:
    """The trial as an ``application/x-hdf5`` request body (one group, ``t``)."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "trial.h5"
        write_biotac_h5(path, {"t": trial})
        return path.read_bytes()


def median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--trials", type=int, default=74, help="how many trials to time")
    args = parser.parse_args()
    configure_threads(1)
    raw = open_dataset(f"biotac:{args.data}")
    model = make_method("best", seed=0).fit(raw)
    featurizer = model.featurizer
    steps: dict[str, list[float]] = {
        "parse": [],
        "parse_hdf5": [],
        "featurize": [],
        "recognize": [],
        "store": [],
    }
    frames = []
    for trial in raw.trials[: args.trials]:
        body = orjson.dumps({"trials": [trial.to_dict()]})
        frames.append(trial.n_frames)
        steps["parse"].append(
            median_ms(lambda b=body: parse_trial(orjson.loads(b)["trials"][0]), args.repeats)
        )
        h5 = hdf5_body(trial)
        steps["parse_hdf5"].append(
            median_ms(lambda b=h5: parse_trial(read_biotac_h5(io.BytesIO(b))["t"]), args.repeats)
        )
        steps["featurize"].append(
            median_ms(lambda t=trial: featurizer.transform([t]), args.repeats)
        )
        images = featurizer.transform([trial]).astype(np.float32)
        groups = np.zeros(len(images), np.int64)
        steps["recognize"].append(
            median_ms(lambda x=images, g=groups: model.recognize_batch(x, groups=g), args.repeats)
        )
        steps["store"].append(median_ms(lambda t=trial: encode_trial(t), args.repeats))
    medians = {k: statistics.median(v) for k, v in steps.items()}
    total = sum(medians[k] for k in ("parse", "featurize", "recognize"))
    print(
        json.dumps(
            {
                "trials": len(frames),
                "frames_median": int(statistics.median(frames)),
                "ms_per_trial_median": {k: round(v, 2) for k, v in medians.items()},
                "share_of_an_answer": {
                    k: round(medians[k] / total, 3) for k in ("parse", "featurize", "recognize")
                },
                "featurize_vs_recognize": round(medians["featurize"] / medians["recognize"], 1),
                "json_vs_hdf5_parse": round(medians["parse"] / medians["parse_hdf5"], 1),
                "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
                f"Python {platform.python_version()}",
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
