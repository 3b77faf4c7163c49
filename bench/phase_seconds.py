"""How long each exploration phase of the raw BioTac pilot lasts: the source of the robot
times ``app.data.procedures.SECONDS`` gives the phases tap, hold and squeeze.

For every trial and finger, the phases ``PhaseRule`` finds in its pdc (``RawTrial.
phase_bounds``), in frames, turned into seconds by the trial's own frame rate: its frames
over the span of its whole-second ``timestamps``. Prints each phase's median and quartiles
over the trials' fingers, and the frame rates seen.

    .venv/bin/python -m bench.phase_seconds [--data ../shared/data/biotac_pilot]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from app.data.biotac import load_biotac

DEFAULT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "biotac_pilot"
PHASES = ("tap", "hold", "squeeze")


def phase_seconds(path: Path) -> dict:
    data = load_biotac(path)
    seconds: list[list[float]] = [[] for _ in PHASES]
    rates = []
    for group, trial in zip(data.groups, data.trials, strict=True):
        ts = trial.timestamps
        if ts is None or ts[-1] <= ts[0]:
            raise SystemExit(f"{group}: its timestamps span no time; its frame rate is unknown")
        rate = (trial.n_frames - 1) / float(ts[-1] - ts[0])
        rates.append(rate)
        for bounds in trial.phase_bounds():
            for j, (start, end) in enumerate(bounds):
                seconds[j].append((end - start) / rate)
    out = {"trials": len(data.trials), "frame_rate_hz": _quartiles(rates)}
    out["phases"] = {name: _quartiles(s) for name, s in zip(PHASES, seconds, strict=True)}
    return out


def _quartiles(values: list[float]) -> dict[str, float]:
    q = np.quantile(np.asarray(values, np.float64), [0.25, 0.5, 0.75])
    return {
        "q25": round(float(q[0]), 2),
        "median": round(float(q[1]), 2),
        "q75": round(float(q[2]), 2),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--data", type=Path, default=DEFAULT, help="the biotac_pilot folder")
    args = p.parse_args(argv)
    if not args.data.is_dir():
        p.error(f"no BioTac folder at {args.data}")
    print(json.dumps(phase_seconds(args.data), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
