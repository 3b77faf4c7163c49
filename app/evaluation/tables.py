"""Tables of objects named jointly (``app.framework.tables``), on the splits of
``protocol.evaluate`` (``evaluate --tables``).

A table is a set of distinct objects, each touched k times, whose touches the robot knows
to belong to one object each. Per split:

- ``tables{k}_zsl_joint`` / ``tables{k}_zsl_alone`` (k = 1, 2, 3): tables of every novel
  object of the split, k test trials each (each object's test trials shuffled and dealt k at
  a time; table t takes every object's t-th hand, as many tables as the object with the
  fewest trials fills). Named among the novel classes, as ``zsl`` is: the Hungarian
  assignment over the log of each object's fused ``novel_proba`` (joint), against each
  object's own argmax (alone). The mean accuracy over the split's tables.
- ``tables_mixed_gzsl_seen`` / ``_unseen`` / ``_h`` (joint) and ``tables_mixed_alone_gzsl_*``
  (one by one): ``MIXED_TABLES`` tables per split of every novel object and as many known
  objects (drawn per table), one test trial each. Joint: ``name_table`` at the model's own
  operating point (the novelty score enters the scores); an object named ``UNREGISTERED``
  is wrong. One by one: ``recognize_batch``, each touch routed by its own novelty score, as
  ``gzsl`` is. The known objects' answers and the novel objects' answers are pooled over the
  split's tables before the harmonic mean.

The draws use a generator of their own (``[seed, split, TABLES_STREAM]``), so turning the
tables on leaves every other figure as it was.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.evaluation import metrics
from app.framework.recognizer import TactileRecognizer, group_mean
from app.framework.tables import UNREGISTERED, TableScorer, assign_table, name_table

#: touches per object in the novel objects' tables
TABLE_TOUCHES: tuple[int, ...] = (1, 2, 3)
#: mixed known + novel tables drawn per split
MIXED_TABLES = 10
#: the third word of the tables' random stream (``[seed, split, TABLES_STREAM]``)
TABLES_STREAM = 7

_MIXED = ("gzsl_seen", "gzsl_unseen", "gzsl_h")
TABLE_FIGURES: tuple[str, ...] = (
    tuple(f"tables{k}_zsl_{how}" for k in TABLE_TOUCHES for how in ("joint", "alone"))
    + tuple(f"tables_mixed_{f}" for f in _MIXED)
    + tuple(f"tables_mixed_alone_{f}" for f in _MIXED)
)


def novel_tables(
    labels: np.ndarray, trials: np.ndarray, k: int, rng: np.random.Generator
) -> list[list[np.ndarray]]:
    """Tables of every object of ``labels``, k trials each: a list of tables, each a list
    (one per object, in object order) of the sample indices of its k trials."""
    hands: list[list[np.ndarray]] = []
    for obj in np.unique(labels):
        own = np.unique(trials[labels == obj])
        own = own[rng.permutation(len(own))]
        hands.append(
            [
                np.flatnonzero((labels == obj) & np.isin(trials, own[s : s + k]))
                for s in range(0, len(own) - k + 1, k)
            ]
        )
    n_tables = min(len(h) for h in hands)
    return [[h[t] for h in hands] for t in range(n_tables)]


def joint_accuracy(log_p: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(joint, alone) accuracy of one table: ``log_p`` (objects, classes) against the true
    class of each object."""
    columns, alone, _ = assign_table(log_p, np.zeros(log_p.shape[1], bool))
    return float(np.mean(columns == truth)), float(np.mean(alone == truth))


def measure(
    zsl_model: TactileRecognizer,
    known: tuple[np.ndarray, np.ndarray, np.ndarray],
    novel: tuple[np.ndarray, np.ndarray, np.ndarray],
    known_names: Sequence[str],
    novel_names: Sequence[str],
    rng: np.random.Generator,
    scorer: TableScorer | None = None,
) -> dict[str, float]:
    """The figures of ``TABLE_FIGURES`` for one split. ``known`` and ``novel``: (samples,
    class index, trial id) of the known and the novel test samples; ``scorer``: the mixed
    tables' scoring (``TableScorer()`` by default)."""
    xn, yn, tn = novel
    out: dict[str, float] = {}
    novel_p = zsl_model.novel_proba(xn)
    floor = (scorer or TableScorer()).floor
    for k in TABLE_TOUCHES:
        joint, alone = [], []
        for table in novel_tables(yn, tn, k, rng):
            rows = np.concatenate(table)
            group = np.repeat(np.arange(len(table)), [len(r) for r in table])
            fused = group_mean(novel_p[rows], group, len(table))
            truth = np.array([yn[r[0]] for r in table])
            j, a = joint_accuracy(np.log(np.clip(fused, floor, 1.0)), truth)
            joint.append(j)
            alone.append(a)
        out[f"tables{k}_zsl_joint"] = float(np.mean(joint)) if joint else float("nan")
        out[f"tables{k}_zsl_alone"] = float(np.mean(alone)) if alone else float("nan")
    out.update(mixed(zsl_model, known, novel, known_names, novel_names, rng, scorer))
    return out


def mixed_draws(
    yk: np.ndarray, yn: np.ndarray, rng: np.random.Generator, n_tables: int = MIXED_TABLES
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n_tables`` draws, each (known, novel) sample indices: one test trial of each of as
    many known objects as there are novel objects, and one of each novel object."""
    objects_k, objects_n = np.unique(yk), np.unique(yn)
    size = min(len(objects_k), len(objects_n))
    draws = []
    for _ in range(n_tables):
        chosen = rng.choice(objects_k, size, replace=False)
        ki = [rng.choice(np.flatnonzero(yk == o)) for o in chosen]
        ni = [rng.choice(np.flatnonzero(yn == o)) for o in objects_n]
        draws.append((np.array(ki, np.int64), np.array(ni, np.int64)))
    return draws


def mixed(
    zsl_model: TactileRecognizer,
    known: tuple[np.ndarray, np.ndarray, np.ndarray],
    novel: tuple[np.ndarray, np.ndarray, np.ndarray],
    known_names: Sequence[str],
    novel_names: Sequence[str],
    rng: np.random.Generator,
    scorer: TableScorer | None = None,
    n_tables: int = MIXED_TABLES,
) -> dict[str, float]:
    """The ``tables_mixed_*`` figures (the module docstring)."""
    (xk, yk, _), (xn, yn, _) = known, novel
    truth, joint, alone, is_known = [], [], [], []
    for ki, ni in mixed_draws(yk, yn, rng, n_tables):
        x = np.concatenate([xk[ki], xn[ni]])
        names = [known_names[j] for j in yk[ki]] + [novel_names[j] for j in yn[ni]]
        answers, columns = name_table(zsl_model, x, list(range(len(x))), scorer=scorer)
        joint += [columns[a.column] for a in answers]
        batch = zsl_model.recognize_batch(x, top_k=1)
        alone += [batch.class_names[i] for i in batch.top_index[:, 0]]
        truth += names
        is_known += [True] * len(ki) + [False] * len(ni)
    joint = ["" if c is UNREGISTERED else c for c in joint]
    out = {f"tables_mixed_{k}": v for k, v in metrics.gzsl_figures(truth, joint, is_known).items()}
    for k, v in metrics.gzsl_figures(truth, alone, is_known).items():
        out[f"tables_mixed_alone_{k}"] = v
    return out
