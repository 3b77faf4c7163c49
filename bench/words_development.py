"""The reader on the development set: 51 everyday objects outside PHAC-2, labelled by hand.

    .venv/bin/python -m bench.words_development [--lexicon PATH]

Agreement (balanced accuracy per attribute, averaged; absent counts as "has not") of the
values read from ``bench/data/everyday_descriptions.csv`` with its hand labels, read alone
and with the unmentioned attributes estimated from PHAC-2's 60 objects as known classes.
This is the set the lexicon was developed on: its figures are not a test.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

DEVELOPMENT = Path(__file__).resolve().parent / "data" / "everyday_descriptions.csv"


def main(argv: list[str] | None = None) -> int:
    from app.data.phac2 import load_phac2
    from app.data.sources import default_phac2_path
    from bench.words_phac2 import agreement, text_vectors

    parser = argparse.ArgumentParser(prog="bench.words_development")
    parser.add_argument("--lexicon", type=Path, default=None)
    args = parser.parse_args(argv)
    dataset = load_phac2(default_phac2_path())
    attrs = tuple(dataset.attribute_names)
    with open(DEVELOPMENT, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    truth = np.array([[a in r["attributes"].split() for a in attrs] for r in rows], np.float32)
    texts = [r["sentence"] for r in rows]
    read = text_vectors(texts, attrs, lexicon=args.lexicon)
    full = text_vectors(texts, attrs, lexicon=args.lexicon, known=dataset.class_attributes)
    report = {
        "read": agreement(read, truth)["balanced_accuracy"],
        "read_and_estimated": agreement(full, truth)["balanced_accuracy"],
        "coverage_read": float((~np.isnan(read)).mean()),
    }
    print(json.dumps(report, indent=1))
    missed = {
        a: [r["name"] for r, t, v in zip(rows, truth[:, j], read[:, j], strict=True)
            if t and not np.nan_to_num(v) >= 0.5]
        for j, a in enumerate(attrs)
    }  # fmt: skip
    print(json.dumps({a: m for a, m in missed.items() if m}, indent=0))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
