"""A table of objects answered at once: ``POST /v1/recognize`` with ``objects`` and
``tactile-zsl recognize --objects`` (docs/TABLES.md).

The caller labels each sample (or raw trial) with the physical object it touched; distinct
labels are distinct objects. ``app.framework.tables.name_table`` names the objects jointly
(no class, known or novel, given to two objects; "novel, not any registered class" may
repeat). Each object's other fields (novelty score, top k, procedures, input health, the
operating point) are those of its touches fused, as ``same_object`` gives them for one
object. Both the route and the command build their answers here, so they agree.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from app.framework.recognizer import (
    ABSTAIN,
    TARGET_CONFIDENCE,
    RecognitionBatch,
    TactileRecognizer,
)

#: the longest label taken, in characters (a class name's limit)
MAX_LABEL = 200
# an integer label is echoed back in JSON: orjson writes 64-bit integers only
_INT_RANGE = (-(2**63), 2**63 - 1)
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")

Label = str | int


class LabelError(ValueError):
    """Object labels that cannot be used; ``field`` names where (``objects``,
    ``objects[3]``). The message says what to send instead."""

    def __init__(self, message: str, field: str = "objects") -> None:
        super().__init__(message)
        self.field = field


def split_labels(text: str) -> list[str]:
    """The labels of a comma-separated list (a query parameter, a header, ``--objects``),
    each stripped of surrounding spaces; [] for a blank text."""
    return [] if not text.strip() else [part.strip() for part in text.split(",")]


def check_labels(labels: Any, n: int, what: str = "samples") -> list[Label]:
    """``labels`` when they are one non-empty string or integer for each of the ``n``
    ``what`` (``samples`` or ``trials``); a ``LabelError`` naming the first problem and
    its fix otherwise."""
    one = what.removesuffix("s")
    if not isinstance(labels, list):
        raise LabelError(
            f"objects: expected a list of labels, one per {one}, got {_type(labels)}", "objects"
        )
    if not labels:
        raise LabelError(
            f"objects: no labels given; give one label per {one} ({n} {what}), the object "
            f"each was touched on, or leave objects out for one answer per {one}",
            "objects",
        )
    for i, label in enumerate(labels):
        field = f"objects[{i}]"
        if isinstance(label, bool) or not isinstance(label, str | int):
            raise LabelError(
                f"{field}: a label is a string or an integer naming the object, got {_type(label)}",
                field,
            )
        if isinstance(label, int) and not _INT_RANGE[0] <= label <= _INT_RANGE[1]:
            raise LabelError(
                f"{field}: an integer label must fit in 64 bits; use a string for longer ids",
                field,
            )
        if isinstance(label, str):
            if not label.strip():
                raise LabelError(
                    f"{field}: the label is empty; name the object of every {one} "
                    "(a non-empty string or an integer)",
                    field,
                )
            if len(label) > MAX_LABEL:
                raise LabelError(f"{field}: at most {MAX_LABEL} characters taken", field)
            if _CONTROL.search(label):
                raise LabelError(f"{field}: a label holds no control characters", field)
    if len(labels) != n:
        raise LabelError(
            f"objects: {len(labels)} labels for {n} {what}; give exactly one label per "
            f"{one}, in the order of the {what}",
            "objects",
        )
    return labels


def _type(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, float):  # orjson reads integers beyond 64 bits as floats too
        return f"the number {value!r}"
    return {bool: "true or false", list: "a list", dict: "an object"}.get(
        type(value), type(value).__name__
    )


class Table(NamedTuple):
    """A table's answer: ``batch`` holds one row per object of ``objects`` (the distinct
    labels in order of first appearance), its touches fused; ``answers`` the joint naming
    of each (``app.framework.tables.TableAnswer``; None for an object that abstains on an
    input outlier, left out of the naming), ``columns`` the names of the classes it
    assigns (``None``: novel, not any registered class); ``touches`` how many samples (or
    trials) each object has."""

    batch: RecognitionBatch
    objects: list[Label]
    answers: list[Any]
    columns: list[str | None]
    touches: list[int]


def answer_table(
    rec: TactileRecognizer,
    objects: Sequence[Label],
    samples: Any = None,
    trials: Sequence[Any] | None = None,
    top_k: int = 3,
    target_confidence: float | None = None,
    known_kept: float | None = None,
    outliers: str = ABSTAIN,
) -> Table:
    """Name the objects of ``samples`` (or of raw ``trials``, featurized by the model's
    featurizer: a trial's fingers are touches of its object) jointly, one label of
    ``objects`` per sample or trial (``check_labels`` first).

    An object whose fused answer abstains on an input outlier (``outliers`` ``abstain``)
    takes no part in the naming: a broken sensor's touches are no evidence, and must not
    take a class from an object touched well."""
    from app.framework.tables import name_table

    if trials is not None:
        x, trial_of = rec.trial_samples(list(trials))
        labels = [objects[t] for t in trial_of.tolist()]
    else:
        x = rec.validate_samples(samples, partial=True)
        labels = list(objects)
    order: dict[Label, int] = {}
    counts: list[int] = []
    for label in objects:  # trials (or samples) per object: the touches its answer fuses
        if label not in order:
            order[label] = len(order)
            counts.append(0)
        counts[order[label]] += 1
    groups = np.fromiter((order[label] for label in labels), np.int64, len(labels))
    target = TARGET_CONFIDENCE if target_confidence is None else target_confidence
    batch = rec.recognize_batch(
        x, top_k, groups, target, known_kept, touches=np.asarray(counts, np.int64)
    )
    named = np.ones(len(order), bool)
    if outliers == ABSTAIN and batch.input_outlier is not None:
        named = ~batch.input_outlier
    answers: list[Any] = [None] * len(order)
    columns: list[str | None] = []
    if named.any():
        rows = named[groups]
        table, columns = name_table(
            rec, x[rows], [lab for lab, r in zip(labels, rows, strict=True) if r], known_kept
        )
        for answer in table:
            answers[order[answer.object]] = answer
    return Table(batch, list(order), answers, list(columns), counts)


def table_records(
    table: Table,
    records: list[dict[str, Any]],
    label: Callable[[str], Mapping[str, Any]],
    kinds: Mapping[str, str],
) -> list[dict[str, Any]]:
    """``records`` (the fused batch's, one per object) as a table's answers: each named by
    the joint assignment, with ``object``, ``alone``, ``margin`` and ``touches``.
    ``label(name)``: a class's label fields (``class_name``, and ``class_id`` on the
    service); ``kinds``: ``known`` or ``novel`` by class name. An answer that abstained on
    an input outlier names no class, and its ``alone`` and ``margin`` are None."""
    out = []
    for record, obj, answer, touches in zip(
        records, table.objects, table.answers, table.touches, strict=True
    ):
        alone = margin = None
        if answer is not None:
            record.update(_named(table.columns[answer.column], record, label, kinds))
            alone = _named(table.columns[answer.alone], record, label, kinds)
            margin = float(answer.margin) if math.isfinite(answer.margin) else None
        record.update(object=obj, alone=alone, margin=margin, touches=touches)
        out.append(record)
    return out


def _named(
    name: str | None,
    record: Mapping[str, Any],
    label: Callable[[str], Mapping[str, Any]],
    kinds: Mapping[str, str],
) -> dict[str, Any]:
    """The label fields and kind of a column: a class, or (``name`` None) novel, not any
    registered class."""
    if name is None:
        return {**{k: None for k in ("class_id", "class_name") if k in record}, "kind": "novel"}
    return {**label(name), "kind": kinds[name]}


def table_body(
    rec: TactileRecognizer,
    meta: Mapping[str, Any],
    objects: Sequence[Any],
    samples: Any,
    top_k: int = 3,
    target_confidence: float | None = None,
    known_kept: float | None = None,
    outliers: str = ABSTAIN,
) -> dict[str, Any]:
    """``POST /v1/recognize``'s body for a table, answered by a model file away from the
    service (the client's offline model, the ROS 2 bridge's ``--model``): ``meta`` is the
    file's description (``version``, ``class_ids``); ``known_kept`` the operating point
    as ``TactileRecognizer.operating_point`` gives it. LabelError for bad labels."""
    x = rec.validate_samples(samples, partial=True)
    labels = check_labels(objects, len(x))
    table = answer_table(rec, labels, x, None, top_k, target_confidence, known_kept, outliers)
    ids = meta.get("class_ids", {})
    batch = table.batch
    results = table_records(
        table,
        batch.records(ids, outliers),
        lambda name: {"class_id": ids.get(name), "class_name": name},
        dict(zip(batch.class_names, batch.class_kinds, strict=True)),
    )
    return {"model_version": meta.get("version"), "results": results}
