"""The PHAC-2 splits the exploration scripts of ``bench/research`` run on: their shared
command-line arguments (``--data --seeds --novel --splits --tiny``) and the loop over seeds
and splits.

``--tiny`` is the smoke-test size (``tests/bench/test_research_smoke.py``): one split of
the first seed, and each script's costly loops (epochs, trees, folds) cut short through
``tiny``. Its figures mean nothing; it shows that a script still runs against ``app``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.data.dataset import TactileDataset
from app.evaluation.splits import ZslSplit, make_zsl_splits

DEFAULT_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "phac2"


def add_split_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the PHAC-2 folder")
    parser.add_argument(
        "--seeds",
        default="1,2",
        help="comma-separated split seeds (development: 1,2; 0 is the reported one)",
    )
    parser.add_argument("--novel", type=int, default=6, help="novel objects per split")
    parser.add_argument("--splits", type=int, default=7, help="splits per seed")
    parser.add_argument(
        "--tiny",
        action="store_true",
        help="smoke-test size: one split of the first seed, costly loops cut short "
        "(checks that the script runs; its figures mean nothing)",
    )


def tiny(args: argparse.Namespace, **smaller: object) -> argparse.Namespace:
    """With ``--tiny``: one split of the first of ``--seeds``, and ``smaller``'s values in
    place of those options (e.g. ``epochs=2``). Without it, ``args`` unchanged."""
    if args.tiny:
        args.seeds = args.seeds.split(",")[0]
        args.splits = 1
        for name, value in smaller.items():
            setattr(args, name, value)
    return args


def split_seeds(args: argparse.Namespace, development_only: bool = False) -> list[int]:
    """The ``--seeds``; with ``development_only``, seed 0 (the splits reported until
    2026-11-24; the reporting seed is 1000 since) is refused."""
    seeds = [int(s) for s in args.seeds.split(",")]
    if development_only and 0 in seeds:
        raise SystemExit(
            "seed 0 holds the splits reported until 2026-11-24: use development seeds (1, 2)"
        )
    return seeds


def splits(
    dataset: TactileDataset, args: argparse.Namespace, development_only: bool = False
) -> Iterator[tuple[int, ZslSplit]]:
    """(seed, split) for every split of every seed in ``--seeds``."""
    for seed in split_seeds(args, development_only):
        for split in make_zsl_splits(dataset, args.novel, args.splits, seed):
            yield seed, split


def enrolled_best(dataset: TactileDataset, split: ZslSplit, params: dict | None = None):
    """``best`` (default parameters, or ``params`` in their place; seed 0) fitted on the
    split's known objects, its novel objects enrolled by their attribute vectors (taken ones
    allowed, as PHAC-2 has them)."""
    from app.evaluation.protocol import make_recognizer

    return (
        make_recognizer("best", params, 0)
        .fit(split.train_dataset(dataset))
        .add_novel_classes(
            list(split.novel_names), split.novel_attributes(dataset), allow_known_vectors=True
        )
    )


@dataclass
class ZslCase:
    """One development split as the zero-shot exploration scripts use it: ``best`` (without
    its autoencoder) fitted on its known objects, their scaled inputs ``z``, the novel test
    trials' ``zt`` and labels ``yn``, the novel attribute ``vectors``, and DAP's
    log-posterior as the reference."""

    seed: int
    split: ZslSplit
    train: TactileDataset
    cues: object
    z: np.ndarray
    zt: np.ndarray
    yn: np.ndarray
    vectors: np.ndarray
    log_dap: np.ndarray
    row: dict
    started: float

    def record(self, approach: str, scores: np.ndarray) -> None:
        """Accuracy of ``scores`` (N, novel classes) alone and multiplied with DAP's posterior."""
        scores = scores - scores.max(1, keepdims=True)
        log_p = scores - np.log(np.exp(scores).sum(1, keepdims=True))
        self.row[approach] = float((scores.argmax(1) == self.yn).mean())
        self.row[f"dap*{approach}"] = float(((self.log_dap + log_p).argmax(1) == self.yn).mean())

    def finish(self) -> None:
        self.row["seconds"] = round(time.perf_counter() - self.started, 1)
        print(json.dumps(self.row), file=sys.stderr, flush=True)


def zsl_cases(dataset: TactileDataset, args: argparse.Namespace) -> Iterator[ZslCase]:
    """A ``ZslCase`` per development split."""
    from app.evaluation.protocol import make_recognizer
    from app.methods.known import flatten

    for seed, split in splits(dataset, args, development_only=True):
        started = time.perf_counter()
        train = split.train_dataset(dataset)
        # sae_lambda 0: the reference stays plain DAP, as before 8e8eab5 put the
        # semantic autoencoder into best
        best = make_recognizer("best", {"sae_lambda": 0}, 0).fit(train)
        xn = dataset.samples[split.novel_test_idx]
        yn = split.novel_labels(dataset, split.novel_test_idx)
        vectors = split.novel_attributes(dataset).astype(np.float64)
        p_dap = best.add_novel_classes(
            list(split.novel_names), vectors, allow_known_vectors=True
        ).novel_proba(xn)
        cues = best.known_.cues_model
        yield ZslCase(
            seed,
            split,
            train,
            cues,
            cues.scaled(flatten(train.samples)),
            cues.scaled(flatten(xn)),
            yn,
            vectors,
            np.log(p_dap + 1e-12),
            {"seed": seed, "split": split.index + 1, "dap": float((p_dap.argmax(1) == yn).mean())},
            started,
        )


def print_zsl_means(cases: list[ZslCase], args: argparse.Namespace) -> None:
    """The means over every case's row, the number of splits run and the options (stdout)."""
    rows = [c.row for c in cases]
    mean = {
        k: round(float(np.mean([r[k] for r in rows])), 3)
        for k in rows[0]
        if k not in ("seed", "split", "seconds")
    }
    options = {k: str(v) for k, v in vars(args).items()}  # --splits is the splits per seed
    print(json.dumps({"zsl_mean": mean, "splits_run": len(rows), **options}, indent=2))
