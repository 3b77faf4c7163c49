"""The PHAC-2 splits the issue-5 exploration scripts run on: their shared command-line
arguments (``--data --seeds --novel --splits``) and the loop over seeds and splits."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path

from app.data.dataset import TactileDataset
from app.evaluation.splits import ZslSplit, make_zsl_splits

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "phac2"


def add_split_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the PHAC-2 folder")
    parser.add_argument("--seeds", default="1,2",
                        help="comma-separated split seeds (development: 1,2; 0 is the reported one)")
    parser.add_argument("--novel", type=int, default=6, help="novel objects per split")
    parser.add_argument("--splits", type=int, default=7, help="splits per seed")


def split_seeds(args: argparse.Namespace, development_only: bool = False) -> list[int]:
    """The ``--seeds``; with ``development_only``, seed 0 (the reported splits) is refused."""
    seeds = [int(s) for s in args.seeds.split(",")]
    if development_only and 0 in seeds:
        raise SystemExit("seed 0 holds the reported splits: use development seeds (1, 2)")
    return seeds


def splits(dataset: TactileDataset, args: argparse.Namespace,
           development_only: bool = False) -> Iterator[tuple[int, ZslSplit]]:
    """(seed, split) for every split of every seed in ``--seeds``."""
    for seed in split_seeds(args, development_only):
        for split in make_zsl_splits(dataset, args.novel, args.splits, seed):
            yield seed, split
