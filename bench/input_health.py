"""Input health on held-out trials: how many real samples pass, how many broken ones are
flagged, and what the check adds to an answer's time.

For each source (the simulator, PHAC-2's 600 trials, the BioTac pilot's 74 raw trials)
and each of ``--splits`` seeds from ``--first-seed`` on, a fifth of the trials is held out
whole; the input profile
(``app.framework.input_health.InputProfile``, what ``TactileRecognizer.fit`` keeps) is
fitted on the other trials (for the pilot, after a featurizer fitted on them alone turns
them into images, as a model of raw trials does), and every held-out trial is scored:

- ``pass_rate``: the share of held-out trials whose ``input_outlier`` is false (a raw
  trial's answer comes from both fingers and is an outlier when either is), with a 95 %
  Wilson interval;
- ``flagged``: the share of corrupted held-out trials flagged, per corruption: all zeros,
  saturated (every value at the largest magnitude training held; raw trials: the 12-bit
  full scale 4095 on one finger), scaled by 1e6 and by 1e-6, one dead channel (a row of an
  image, a feature of a flat sample, a raw channel of one finger: at 0, or stuck at its
  first value). A raw trial the featurizer refuses (no contact phases in a flat signal) is
  counted ``refused``: it gets a 422, not an answer; the ``_but_pdc`` corruptions break
  every channel of the finger but the pdc the phases are found in, so that it is answered.
  PHAC-2's dead channels are flagged only where 0 lies outside the feature's training range
  (``dead_channel_detectable``: the share of such features); elsewhere one sample cannot
  tell, and the drift figure over a window can;
- ``drift``: ``InputProfile.window_drift`` over the held-out trials as one window
  (mixed traffic), the largest over channels; over each object's trials alone (a robot
  touching one object again and again), its median and largest; and on the dead
  channel's own figure.

``--timing`` fits the default method (``best``) on the simulator and answers one sample,
and 64, with and without the profile, interleaved in one run, and reports the time added
per sample.

    .venv/bin/python -m bench.input_health [--splits 20] [--first-seed 100] [--timing] [--out FILE]

Writes ``docs/results/input-health/input_health.json`` by default. The threshold and the
scale of sign-keeping statistics (``app.framework.input_health``) were chosen on seeds 0 …
19 (``--first-seed 0``, the simulator's data seed 0); the figures reported are of seeds
100 … 119 and the simulator's data seed 1. PHAC-2 and the pilot have no other trials, so their
evaluation splits hold out other fifths of the same trials.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import subprocess
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from app.data.biotac import RawTrialError, load_biotac
from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset
from app.data.sources import default_phac2_path
from app.framework.input_health import OUTLIER_THRESHOLD, InputProfile

ROOT = Path(__file__).resolve().parents[1]
BIOTAC = ROOT / ".." / "shared" / "data" / "biotac_pilot"
OUT = ROOT / "docs" / "results" / "input-health" / "input_health.json"
HELD_OUT = 0.2
FULL_SCALE = 4095  # the BioTac's 12-bit counts
CORRUPTIONS = ("zeros", "saturated", "scale_1e6", "scale_1e-6", "dead_zero", "dead_stuck")
# a flat sample's channel holds one value: stuck at it is no change
FLAT_CORRUPTIONS = CORRUPTIONS[:-1]
# raw trials whose phases the featurizer still finds: every channel broken but pdc
RAW_CORRUPTIONS = (*CORRUPTIONS, "zeros_but_pdc", "saturated_but_pdc", "scale_1e-6_but_pdc")


def held_out(trial_ids: np.ndarray, seed: int) -> np.ndarray:
    """Bool mask of the samples of a fifth of the trials, drawn whole by ``seed``."""
    trials = np.unique(trial_ids)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(trials, int(round(HELD_OUT * len(trials))), replace=False)
    return np.isin(trial_ids, chosen)


def corrupt(x: np.ndarray, kind: str, top: float, rng: np.random.Generator) -> np.ndarray:
    """``x`` (N, *shape) broken as ``kind`` says; a dead channel is one drawn per sample."""
    if kind == "zeros":
        return np.zeros_like(x)
    if kind == "saturated":
        return np.full_like(x, top)
    if kind.startswith("scale_"):
        return x * np.float32(kind.removeprefix("scale_"))
    out = x.copy()
    for i, c in enumerate(rng.integers(0, x.shape[1], len(x))):
        out[i, c] = 0.0 if kind == "dead_zero" else out[i, c].reshape(-1)[0]
    return out


def samples_source(name: str, x: np.ndarray, trials: np.ndarray, labels: np.ndarray, splits):
    """The figures of a source of fixed-shape samples (one sample per trial)."""
    kinds = FLAT_CORRUPTIONS if x.ndim == 2 else CORRUPTIONS
    passed, flagged, drift = [], {k: [] for k in kinds}, []
    detectable = []
    for seed in splits:
        test = held_out(trials, seed)
        profile = InputProfile.fit(x[~test])
        outlier = profile.score(x[test]) > OUTLIER_THRESHOLD
        passed.append(~outlier)
        top = float(np.abs(x[~test]).max())
        rng = np.random.default_rng(seed)
        for kind in kinds:
            flagged[kind].append(
                profile.score(corrupt(x[test], kind, top, rng)) > OUTLIER_THRESHOLD
            )
        if x.ndim == 2:  # flat samples: can a feature at 0 be told at all?
            detectable.append(float(np.mean((profile.low > 0) | (profile.high < 0))))
        drift.append(_drift(profile, x[test], labels[test], seed))
    out = {"source": name, "held_out_trials": int(sum(len(p) for p in passed))}
    out.update(_rates(passed, flagged))
    if detectable:
        out["dead_channel_detectable"] = round(float(np.mean(detectable)), 3)
    out["drift"] = _mean_drift(drift)
    return out


def _drift(profile: InputProfile, x: np.ndarray, labels: np.ndarray, seed: int) -> dict:
    mixed = profile.window_drift(profile.features(x))
    per_object = [
        float(np.nanmax(profile.window_drift(profile.features(x[labels == c]))))
        for c in np.unique(labels)
    ]
    dead = x.copy()
    channel = seed % x.shape[1]
    dead[:, channel] = 0.0
    dead_drift = profile.window_drift(profile.features(dead))[channel]
    return {
        "mixed_window_max": float(np.nanmax(mixed)),
        "one_object_window_median": float(np.median(per_object)),
        "one_object_window_max": float(np.max(per_object)),
        "dead_channel_at_zero": float(dead_drift),
    }


def _mean_drift(drift: list[dict]) -> dict:
    return {
        k: round(float(np.mean([d[k] for d in drift])), 3)
        if "max" not in k
        else round(float(np.max([d[k] for d in drift])), 3)
        for k in drift[0]
    }


def biotac_source(path: Path, splits: int) -> dict:
    """The pilot's raw trials: profiles fitted on featurized training trials, corruptions
    applied to the raw signals of one finger of each held-out trial."""
    from app.framework.registry import make_method
    from app.framework.tactile_image import featurize_dataset

    data = load_biotac(path)
    passed, flagged = [], {k: [] for k in RAW_CORRUPTIONS}
    refused = dict.fromkeys(RAW_CORRUPTIONS, 0)
    drift = []
    for seed in splits:
        test = held_out(data.trial_ids, seed)
        train = data.subset(np.flatnonzero(~test))
        featurizer = make_method("best")._new_featurizer().fit(train.trials)
        images = featurize_dataset(train, featurizer, augment=True).samples
        profile = InputProfile.fit(images)
        trials = [t for t, m in zip(data.trials, test, strict=True) if m]
        passed.append(np.array([not _trial_outlier(profile, featurizer, t) for t in trials]))
        rng = np.random.default_rng(seed)
        for kind in RAW_CORRUPTIONS:
            verdicts = []
            for t in trials:
                try:
                    verdicts.append(_trial_outlier(profile, featurizer, _broken(t, kind, rng)))
                except RawTrialError:
                    refused[kind] += 1
                    verdicts.append(True)  # not answered: a 422 names the problem
            flagged[kind].append(np.array(verdicts))
        test_images = featurizer.transform(trials)
        labels = np.repeat(data.labels[test], [t.n_fingers for t in trials])
        drift.append(_drift(profile, test_images, labels, seed))
    out = {"source": "biotac_pilot", "held_out_trials": int(sum(len(p) for p in passed))}
    out.update(_rates(passed, flagged))
    out["refused"] = refused
    out["drift"] = _mean_drift(drift)
    return out


def _trial_outlier(profile: InputProfile, featurizer, trial) -> bool:
    """A trial's answer is an outlier where any finger's image is."""
    return bool((profile.score(featurizer.transform([trial])) > OUTLIER_THRESHOLD).any())


def _broken(trial, kind: str, rng: np.random.Generator):
    """``trial`` with finger 0's raw signals broken as ``kind`` says (``_but_pdc``: all
    but its pdc, where the contact phases are found)."""
    finger = trial.fingers[0]
    channels = {c: getattr(finger, c) for c in ("pdc", "tdc", "tac", "pac", "electrodes")}
    if kind.endswith("_but_pdc"):
        broken = _broken(trial, kind.removesuffix("_but_pdc"), rng).fingers[0]
        new = {c: getattr(broken, c) for c in ("tdc", "tac", "pac", "electrodes")}
        fingers = (dataclasses.replace(finger, **new), *trial.fingers[1:])
        return dataclasses.replace(trial, fingers=fingers)
    if kind == "zeros":
        new = {c: np.zeros_like(v) for c, v in channels.items()}
    elif kind == "saturated":
        new = {c: np.full_like(v, FULL_SCALE) for c, v in channels.items()}
    elif kind.startswith("scale_"):
        factor = float(kind.removeprefix("scale_"))
        new = {c: v.astype(np.float64) * factor for c, v in channels.items()}
    else:  # one of the channels the phases are not read from, at 0 or stuck
        name = ("tdc", "tac", "pac", "electrodes")[int(rng.integers(0, 4))]
        value = channels[name]
        stuck = np.zeros_like(value) if kind == "dead_zero" else np.full_like(value, value.flat[0])
        new = {**channels, name: stuck}
    fingers = (dataclasses.replace(finger, **new), *trial.fingers[1:])
    return dataclasses.replace(trial, fingers=fingers)


def _rates(passed: list[np.ndarray], flagged: dict[str, list[np.ndarray]]) -> dict:
    ok = np.concatenate(passed)
    return {
        "pass_rate": round(float(ok.mean()), 4),
        "pass_rate_ci95": wilson(int(ok.sum()), len(ok)),
        "flagged": {k: round(float(np.concatenate(v).mean()), 4) for k, v in flagged.items()},
    }


def wilson(k: int, n: int, z: float = 1.96) -> list[float]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [round(float(centre - half), 4), round(float(min(1.0, centre + half)), 4)]


def timing(rounds: int = 9, calls: int = 200) -> dict:
    """Microseconds per answer of ``best`` (default parameters, fitted on the simulator)
    with and without its input profile, one sample and 64; with it, the service's window
    keeps the samples too (``InputMonitor.observe``), as on the hot path. ``rounds`` blocks
    of ``calls`` answers each way, alternating, the median of each block; the figures are
    the medians over the blocks (the machine is shared: a block that other work slowed
    does not move them)."""
    from app.framework.registry import make_method
    from app.framework.runtime import configure_threads
    from app.service.input_monitor import InputMonitor
    from app.service.metrics import Metrics

    configure_threads()
    data = simulate_dataset(seed=0)
    model = make_method("best").fit(data)
    profile = model.input_profile_
    monitor = InputMonitor(Metrics(), 256)
    out = {}
    for n in (1, 64):
        batch = data.samples[:n]
        blocks: dict[str, list[float]] = {"with": [], "without": []}
        for r in range(rounds):
            for key in ("with", "without") if r % 2 else ("without", "with"):
                model.input_profile_ = profile if key == "with" else None
                times = []
                for _ in range(calls):
                    t0 = time.perf_counter()
                    monitor.observe(model.recognize_batch(batch), model.input_profile_)
                    times.append(time.perf_counter() - t0)
                blocks[key].append(float(np.median(times)) * 1e6 / n)
        model.input_profile_ = profile
        with_us, without_us = (float(np.median(blocks[k])) for k in ("with", "without"))
        added = [w - wo for w, wo in zip(blocks["with"], blocks["without"], strict=True)]
        out[f"batch_{n}"] = {
            "us_per_sample_with": round(with_us, 1),
            "us_per_sample_without": round(without_us, 1),
            "added_us_per_sample": round(float(np.median(added)), 1),
            "added_us_per_sample_blocks": [round(a, 1) for a in added],
            "ratio": round(with_us / without_us, 3),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--splits", type=int, default=20, help="held-out splits per source")
    p.add_argument("--first-seed", type=int, default=100, help="the first split's seed")
    p.add_argument("--timing", action="store_true", help="also time best with and without")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    if args.splits < 1:
        p.error("--splits must be at least 1")
    seeds = range(args.first_seed, args.first_seed + args.splits)
    sim = simulate_dataset(seed=0 if args.first_seed == 0 else 1)
    phac2 = load_phac2(default_phac2_path())
    sources = [
        samples_source("simulator", sim.samples, sim.trials, sim.labels, seeds),
        samples_source("phac2", phac2.samples, phac2.trials, phac2.labels, seeds),
        biotac_source(BIOTAC, seeds),
    ]
    result = {
        "command": "python -m bench.input_health"
        + (f" --splits {args.splits}" if args.splits != 20 else "")
        + (f" --first-seed {args.first_seed}" if args.first_seed != 100 else "")
        + (" --timing" if args.timing else ""),
        "date": datetime.now(UTC).date().isoformat(),
        "commit": _commit(),
        "threshold": OUTLIER_THRESHOLD,
        "held_out_share": HELD_OUT,
        "splits": args.splits,
        "split_seeds": list(seeds),
        "simulator_data_seed": 0 if args.first_seed == 0 else 1,
        "sources": sources,
    }
    if args.timing:
        result["timing"] = {
            "machine": f"{platform.processor() or platform.machine()}, shared with other work",
            **timing(),
        }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    return 0


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
        ).stdout.strip()
    except OSError:
        return ""


if __name__ == "__main__":
    raise SystemExit(main())
