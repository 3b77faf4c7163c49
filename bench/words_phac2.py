"""Objects described in words, measured on real PHAC-2.

    .venv/bin/python -m bench.words_phac2 [--splits 50] [--seed 1000] [--novel 6]
                                          [--out docs/results/words/frozen]

``bench/data/phac2_descriptions_2026-11-28.csv`` (``--descriptions``) gives each of the 60
objects a name and a sentence, written from general knowledge of its material after the
reader's lexicon and estimator were frozen (3b1d1e5 froze them; 0f2941c added the texts),
never from the adjective labels. ``app.words`` reads both into the 19 attributes (absent:
not known). ``tuned sentence`` reads the same sentences with the lexicon written beside the
first PHAC-2 descriptions (8a358d9, kept as ``bench/data/lexicon_tuned_2026-11-25.json``):
the before and after of one command. ``…+estimated``: the attributes a sentence does not
mention estimated from each split's known objects (``app.words.estimate``, as the service
does from its live classes); their agreement is pooled over every split's novel objects.

- **Agreement** with the true adjectives: per attribute, the balanced accuracy over the 60
  objects of "read with a value of 0.5 or more" (absent counts as no), then the mean over
  attributes; and the coverage (attribute values read) and the accuracy where read.
- **Zero-shot on the evaluation splits** (``make_zsl_splits``: ``--splits`` splits,
  ``--novel`` novel objects each, 2 held-out trials per known object, ``best`` with each
  split's method seed, as ``tactile-zsl evaluate`` runs it): the novel objects registered by
  their true attribute vectors (``vector``), by their sentences (``sentence``) and by their
  names (``name``); zsl and gzsl_h, each paired against ``vector`` over the same splits
  (mean difference and its 95 % interval). Two novel objects whose texts give the same
  vector are registered 0.001 apart (the service would answer the second with a 409), and
  an object whose text gives no value above 0 (the service: a 422) with the known objects'
  mean vector; ``unread`` counts them.
- **Text as side information** (``sentence+embedding``): beside the values read, the
  sentence's own embedding as a class embedding: a semantic autoencoder (``best``'s, same
  λ) from the scaled samples to the known objects' sentence embeddings, its cosine with a
  novel object's sentence embedding added to the zero-shot log scores at ``best``'s
  ``sae_temperature``. Fixed a priori, not tuned.

Writes ``words.json`` and ``words.png`` to ``--out`` and prints the tables.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"
#: written after the reader was frozen (3b1d1e5): the test texts
DESCRIPTIONS = DATA / "phac2_descriptions_2026-11-28.csv"
#: the lexicon that was written beside the first PHAC-2 descriptions (8a358d9)
TUNED_LEXICON = DATA / "lexicon_tuned_2026-11-25.json"
KINDS = (
    "vector",
    "sentence",
    "sentence+estimated",
    "tuned sentence",
    "tuned sentence+estimated",
    "name",
    "sentence+embedding",
)
#: kinds whose unmentioned attributes are estimated from each split's known classes
ESTIMATED = {"sentence+estimated": "sentence", "tuned sentence+estimated": "tuned sentence"}
#: kind -> the kind it is paired against beside ``vector``
PAIRED = {
    **ESTIMATED,
    "sentence+embedding": "sentence",
    "sentence": "tuned sentence",
}


def read_descriptions(path: Path = DESCRIPTIONS) -> dict[int, dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return {int(r["object_id"]): r for r in csv.DictReader(f)}


def text_vectors(
    texts: list[str],
    attributes: tuple[str, ...],
    lexicon: Path | None = None,
    known: np.ndarray | None = None,
) -> np.ndarray:
    """(len(texts), M) values read from each text, NaN where it says nothing; with
    ``known`` (K, M) known classes' vectors, the attributes it does not mention estimated
    from them (``app.words.estimate``). ``lexicon``: None, the frozen one."""
    from app.words.estimate import UnmentionedEstimator
    from app.words.interpret import NothingRecognised, TextInterpreter

    reader = TextInterpreter(lexicon=lexicon)
    estimator = None if known is None else UnmentionedEstimator().fit(known, attributes)
    out = np.full((len(texts), len(attributes)), np.nan, np.float32)
    for i, text in enumerate(texts):
        try:
            read = reader.interpret(text, attributes)
        except NothingRecognised:
            continue
        values = {a: r.value for a, r in read.items()}
        if estimator is not None:
            values.update(estimator.estimate(values))
        for j, a in enumerate(attributes):
            if a in values:
                out[i, j] = values[a]
    return out


def agreement(read: np.ndarray, truth: np.ndarray) -> dict:
    """Balanced accuracy per attribute (absent = no), its mean, coverage, accuracy where read."""
    said = np.nan_to_num(read, nan=0.0) >= 0.5
    true = truth >= 0.5
    per = []
    for j in range(truth.shape[1]):
        pos, neg = true[:, j], ~true[:, j]
        tpr = said[pos, j].mean() if pos.any() else np.nan
        tnr = (~said[neg, j]).mean() if neg.any() else np.nan
        per.append(float(np.nanmean([tpr, tnr])))
    known = ~np.isnan(read)
    right = (read >= 0.5) == true
    return {
        "balanced_accuracy": float(np.mean(per)),
        "per_attribute": per,
        "coverage": float(known.mean()),
        "accuracy_where_read": float(right[known].mean()) if known.any() else float("nan"),
    }


def _distinct(vectors: np.ndarray) -> np.ndarray:
    """Rows made pairwise different by 0.001 on their first value where they coincide."""
    v = vectors.copy()
    for i in range(len(v)):
        while any(np.array_equal(v[i], v[j], equal_nan=True) for j in range(i)):
            col = int(np.argmax(~np.isnan(v[i]))) if (~np.isnan(v[i])).any() else 0
            base = 0.5 if np.isnan(v[i, col]) else float(v[i, col])
            v[i, col] = base - 0.001 if base >= 0.001 else base + 0.001
    return v


def run_split(dataset, split, seed: int, by_kind: dict[str, np.ndarray], text_emb: np.ndarray):
    from app.evaluation import metrics
    from app.evaluation.protocol import make_recognizer, split_method_seed
    from app.framework.scaling import flatten
    from app.methods.attributes import cosine_scores, semantic_autoencoder, softmax

    train = split.train_dataset(dataset)
    model = make_recognizer("best", None, split_method_seed(seed, split.index)).fit(train)
    xk, yk = (
        dataset.samples[split.known_test_idx],
        split.known_labels(dataset, split.known_test_idx),
    )
    xn, yn = (
        dataset.samples[split.novel_test_idx],
        split.novel_labels(dataset, split.novel_test_idx),
    )
    names = list(split.novel_names)
    novel = np.asarray(split.novel_classes)
    known_names = list(train.class_names)
    out: dict = {"novel": novel.tolist()}
    z_train = model.known_.cues_model.scaled(flatten(train.samples))
    emb_known = text_emb[np.asarray(split.known_classes)]
    w = semantic_autoencoder(z_train, emb_known[train.labels], float(model.sae_lambda))
    from app.words.estimate import UnmentionedEstimator

    estimator = UnmentionedEstimator().fit(
        dataset.class_attributes[np.asarray(split.known_classes)], dataset.attribute_names
    )
    estimated = {}
    for kind, source in ESTIMATED.items():
        rows = by_kind[source][novel].copy()
        attrs = list(dataset.attribute_names)
        for row in rows:
            said = {a: float(v) for a, v in zip(attrs, row, strict=True) if not np.isnan(v)}
            guess = estimator.estimate(said)
            row[:] = [guess.get(a, v) for a, v in zip(attrs, row, strict=True)]
        estimated[kind] = rows
    out["estimated"] = {k: v.tolist() for k, v in estimated.items()}
    for kind in KINDS:
        source = "sentence" if kind == "sentence+embedding" else kind
        vectors = estimated[kind] if kind in ESTIMATED else by_kind[source][novel].copy()
        empty = ~(np.nan_to_num(vectors, nan=0.0) > 0).any(axis=1)
        vectors[empty] = model.prior_  # nothing read (the service: a 422): the known prior
        vectors = _distinct(vectors)
        m = model.add_novel_classes(names, vectors, allow_known_vectors=True)
        p = m.novel_proba(xn)
        if kind == "sentence+embedding":
            zn = m.known_.cues_model.scaled(flatten(xn))
            extra = float(model.sae_temperature) * cosine_scores(zn, w, text_emb[novel])
            p = softmax(np.log(np.clip(p, 1e-300, None)) + extra)
        figures = {"zsl": metrics.accuracy(yn, p.argmax(axis=1))}
        if kind != "sentence+embedding":
            answers = m.recognize(np.concatenate([xk, xn]), top_k=1, outliers="answer")
            true = [known_names[j] for j in yk] + [names[j] for j in yn]
            is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
            figures["gzsl_h"] = metrics.gzsl_figures(
                true, [a.class_name for a in answers], is_known
            )["gzsl_h"]
        out[kind] = figures
    return out


def summary(per_split: list[dict]) -> dict:
    from app.evaluation import metrics

    out = {}
    for kind in KINDS:
        out[kind] = {}
        for fig in ("zsl", "gzsl_h"):
            values = [s[kind].get(fig) for s in per_split]
            if values[0] is None:
                continue
            ref = [s["vector"][fig] for s in per_split]
            diff = metrics.paired_differences(values, ref)
            out[kind][fig] = {
                "mean": float(np.mean(values)),
                "ci95": list(metrics.mean_interval(values, bounds=(0.0, 1.0))),
                "vs_vector": float(np.nanmean(diff)),
                "vs_vector_ci95": list(metrics.mean_interval(diff)),
                "ratio_to_vector": float(np.mean(values) / np.mean(ref)),
            }
            # paired against the reading they add to: what the embedding or the estimates
            # add to the values read, and the frozen lexicon against the tuned one
            base = PAIRED.get(kind)
            if base is not None:
                diff = metrics.paired_differences(values, [s[base][fig] for s in per_split])
                key = "vs_" + base.replace(" ", "_")
                out[kind][fig][key] = float(np.nanmean(diff))
                out[kind][fig][key + "_ci95"] = list(metrics.mean_interval(diff))
    return out


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
    attrs = report["attributes"]
    x = np.arange(len(attrs))
    for i, kind in enumerate(("sentence", "sentence+estimated")):
        a1.bar(x + (i - 0.5) * 0.4, report["agreement"][kind]["per_attribute"], 0.4, label=kind)
    a1.axhline(0.5, color="grey", lw=0.8, ls=":")
    a1.set_xticks(x, attrs, rotation=75, fontsize=8)
    a1.set_ylabel("balanced accuracy")
    a1.set_title("values read from text against PHAC-2's adjectives")
    a1.legend()
    s = report["summary"]
    for j, fig_name in enumerate(("zsl", "gzsl_h")):
        kinds = [k for k in KINDS if fig_name in s[k]]
        means = [s[k][fig_name]["mean"] for k in kinds]
        err = np.array(
            [[m - s[k][fig_name]["ci95"][0], s[k][fig_name]["ci95"][1] - m] for k, m in
             zip(kinds, means, strict=True)]
        ).T  # fmt: skip
        a2.bar(np.arange(len(kinds)) + (j - 0.5) * 0.4, means, 0.4, yerr=err, label=fig_name)
    a2.set_xticks(np.arange(len(KINDS)), KINDS, fontsize=7, rotation=30, ha="right")
    a2.set_title(f"novel objects registered by …, {report['splits']} splits")
    a2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench.words_phac2", description=__doc__.split("\n")[0])
    parser.add_argument("--splits", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--novel", type=int, default=6)
    parser.add_argument("--out", type=Path, default=Path("docs/results/words/frozen"))
    parser.add_argument("--descriptions", type=Path, default=DESCRIPTIONS)
    args = parser.parse_args(argv)
    if args.splits < 2 or args.novel < 2:
        parser.error("--splits and --novel must be at least 2")
    from app.data.phac2 import load_phac2
    from app.data.sources import default_phac2_path
    from app.evaluation.splits import make_zsl_splits
    from app.words.embedding import shared_embedder

    try:
        dataset = load_phac2(default_phac2_path())
        texts = read_descriptions(args.descriptions)
    except (OSError, ValueError, KeyError) as exc:
        print(f"bench.words_phac2: {exc}", file=sys.stderr)
        return 2
    ids = [int(i) for i in dataset.object_ids]
    missing = [i for i in ids if i not in texts]
    if missing:
        print(f"bench.words_phac2: no description for objects {missing[:5]}", file=sys.stderr)
        return 2
    attrs = tuple(dataset.attribute_names)
    by_kind = {
        "vector": dataset.class_attributes.astype(np.float32),
        "sentence": text_vectors([texts[i]["sentence"] for i in ids], attrs),
        "tuned sentence": text_vectors(
            [texts[i]["sentence"] for i in ids], attrs, lexicon=TUNED_LEXICON
        ),
        "name": text_vectors([texts[i]["name"] for i in ids], attrs),
    }
    text_emb = shared_embedder().encode([texts[i]["sentence"] for i in ids])
    unread = {
        k: int((~(np.nan_to_num(by_kind[k], nan=0.0) > 0).any(axis=1)).sum())
        for k in ("sentence", "tuned sentence", "name")
    }
    import subprocess

    def git(*cmd: str) -> str:
        return subprocess.run(["git", *cmd], capture_output=True, text=True).stdout.strip()

    report = {
        "command": " ".join(["python -m bench.words_phac2", *(argv or sys.argv[1:])]),
        "commit": git("rev-parse", "--short", "HEAD"),
        "dirty": bool(git("status", "--porcelain", "--", "app", "bench", "worker")),
        "unread": unread,
        "splits": args.splits,
        "seed": args.seed,
        "novel": args.novel,
        "attributes": list(attrs),
        "descriptions": str(args.descriptions),
        "agreement": {
            k: agreement(by_kind[k], dataset.class_attributes)
            for k in ("sentence", "tuned sentence", "name")
        },
    }
    splits = make_zsl_splits(dataset, args.novel, args.splits, args.seed)
    per_split = []
    for i, split in enumerate(splits):
        per_split.append(run_split(dataset, split, args.seed, by_kind, text_emb))
        print(f"split {i + 1}/{len(splits)}", file=sys.stderr)
    for kind in ESTIMATED:  # each novel object as its split's known classes estimate it
        rows = np.concatenate([np.asarray(s["estimated"][kind]) for s in per_split])
        truth = np.concatenate([dataset.class_attributes[s["novel"]] for s in per_split])
        report["agreement"][kind] = agreement(rows, truth)
        report["agreement"][kind]["pooled_over"] = "the novel objects of every split"
    report["per_split"] = per_split
    report["summary"] = summary(per_split)
    report["targets"] = {
        "zsl_sentence+estimated_over_vector": report["summary"]["sentence+estimated"]["zsl"][
            "ratio_to_vector"
        ],
        "agreement_sentence+estimated": report["agreement"]["sentence+estimated"][
            "balanced_accuracy"
        ],
        "goal": "ratio >= 0.9, agreement >= 0.80",
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "words.json").write_text(json.dumps(report, indent=1))
    plot(report, args.out / "words.png")
    print("| text | balanced accuracy | coverage | accuracy where read |")
    print("| --- | --- | --- | --- |")
    for k in report["agreement"]:
        a = report["agreement"][k]
        print(f"| {k} | {a['balanced_accuracy']:.3f} | {a['coverage']:.3f} | "
              f"{a['accuracy_where_read']:.3f} |")  # fmt: skip
    print()
    print("| registered by | zsl | vs vector | gzsl_h | vs vector |")
    print("| --- | --- | --- | --- | --- |")
    for k in KINDS:
        cells = []
        for fig in ("zsl", "gzsl_h"):
            f = report["summary"][k].get(fig)
            if f is None:
                cells += ["–", "–"]
                continue
            lo, hi = f["ci95"]
            dlo, dhi = f["vs_vector_ci95"]
            cells += [
                f"{f['mean']:.3f} [{lo:.3f}, {hi:.3f}]",
                f"{f['vs_vector']:+.3f} [{dlo:+.3f}, {dhi:+.3f}]",
            ]
        print(f"| {k} | " + " | ".join(cells) + " |")
    print()
    for kind, base in PAIRED.items():
        key = "vs_" + base.replace(" ", "_")
        for fig in ("zsl", "gzsl_h"):
            f = report["summary"][kind].get(fig)
            if f is not None:
                lo, hi = f[key + "_ci95"]
                print(f"{kind} against {base}, {fig}: {f[key]:+.3f} [{lo:+.3f}, {hi:+.3f}]")
    t = report["targets"]
    print(f"zsl by sentence+estimated / by vector: {t['zsl_sentence+estimated_over_vector']:.3f}; "
          f"agreement: {t['agreement_sentence+estimated']:.3f} ({t['goal']})")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
