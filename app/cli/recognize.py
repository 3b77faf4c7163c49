"""``tactile-zsl recognize``: recognise samples with a model bundle file, without a service."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, NamedTuple, TextIO


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "recognize",
        help="recognise samples offline with a model bundle",
        description="Recognise samples with a model bundle file (written by 'train', or downloaded "
        "from a service with GET /v1/models/{version}/bundle) and print the answers as JSON, in "
        "the shape of POST /v1/recognize's results: on a robot without the network, the same "
        "answers the service gives.",
    )
    p.add_argument("--model", required=True, type=Path, help="the model bundle file")
    p.add_argument(
        "samples",
        help="a .npy file (one sample, or N samples of the model's input shape), a .json "
        'file ({"samples": [...]} as the API takes, or {"trials": [...]}: raw BioTac trials '
        "for a model trained on raw trials, one answer per trial), or - for that JSON on stdin",
    )
    p.add_argument("--top-k", type=int, default=3, help="scores to list per sample (default 3)")
    p.add_argument(
        "--objects",
        metavar="LABELS",
        help="a table of objects (docs/TABLES.md): the object each sample (or trial) was "
        "touched on, comma-separated, one per sample in order (cup,box,cup); the objects are "
        "named jointly, one answer per object, as POST /v1/recognize?objects= answers. A JSON "
        'request may give them as its "objects" list instead (with --lines, per line)',
    )
    p.add_argument(
        "--lines",
        action="store_true",
        help="read one JSON request per line from SAMPLES (- for stdin) and answer each "
        "on its own line at once, until the input ends: one process serves a robot "
        "without paying its start-up per touch. A bad line is answered "
        '{"error": ...} and the process goes on; the model file is read again '
        "whenever it changes (after a sync)",
    )
    p.set_defaults(handler=run)


def read_samples(source: str):
    """The samples in ``source`` (.npy, .json or - for JSON on stdin) as an array or lists."""
    import numpy as np

    if source == "-":
        return _from_json(sys.stdin.read(), "stdin")
    path = Path(source)
    if not path.is_file():
        raise ValueError(f"no samples file at {path}")
    if path.suffix == ".npy":
        try:
            return np.load(path, allow_pickle=False)  # never unpickles: object arrays are refused
        except (ValueError, EOFError) as exc:
            raise ValueError(f"{path} is not a readable .npy array: {exc}") from None
    if path.suffix == ".json":
        return _from_json(path.read_text(), str(path))
    raise ValueError(f"{path}: samples must be a .npy or .json file")


class Trials(list):
    """Raw trials read from a request's ``"trials"`` (answered one per trial)."""


class Labelled(NamedTuple):
    """A table's request: its samples (or ``Trials``) and the object label of each."""

    request: Any
    objects: Any


def _from_json(text: str, where: str):
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where} is not JSON: {exc}") from None
    if isinstance(data, dict) and isinstance(data.get("trials"), list) and "samples" not in data:
        return _labelled(Trials(data["trials"]), data)
    if not isinstance(data, dict) or "samples" not in data:
        raise ValueError(f'{where} must hold an object {{"samples": [...]}} or {{"trials": [...]}}')
    return _labelled(data["samples"], data)


def _labelled(request: Any, data: dict) -> Any:
    """``request``, with its table's labels where ``data`` gives ``objects``."""
    return request if data.get("objects") is None else Labelled(request, data["objects"])


def with_objects(request: Any, labels: str | None) -> Any:
    """``request`` labelled with ``--objects`` (comma-separated), where given; a request's
    own ``objects`` must agree."""
    from app.service.table_answers import split_labels

    if labels is None:
        return request
    objects = split_labels(labels)
    if isinstance(request, Labelled):
        if request.objects != objects:
            raise ValueError(
                'the request\'s "objects" and --objects give different labels; give them once'
            )
        return request
    return Labelled(request, objects)


def answers(model, request, top_k: int):
    """A model's answers to samples, or to raw trials (one per trial), at the service's
    default operating point (``TactileRecognizer.operating_point``)."""
    kept = model.operating_point()
    if isinstance(request, Trials):
        return model.recognize_trials(list(request), top_k=top_k, known_kept=kept)
    return model.recognize_batch(request, top_k=top_k, known_kept=kept)


def results(model, request, top_k: int) -> list[dict[str, Any]]:
    """The ``results`` printed for a request: one per sample or trial, or for a table
    (``Labelled``), one per object, as ``POST /v1/recognize`` answers them (without the
    store's class ids)."""
    from app.service.table_answers import answer_table, check_labels, table_records

    if not isinstance(request, Labelled):
        return answers(model, request, top_k).records()
    request, objects = request
    trials = list(request) if isinstance(request, Trials) else None
    samples = None if trials is not None else model.validate_samples(request, partial=True)
    what = "trials" if trials is not None else "samples"
    labels = check_labels(objects, len(trials if trials is not None else samples), what)
    kept = model.operating_point()
    table = answer_table(model, labels, samples, trials, top_k, known_kept=kept)
    batch = table.batch
    kinds = dict(zip(batch.class_names, batch.class_kinds, strict=True))
    return table_records(table, batch.records(), lambda name: {"class_name": name}, kinds)


def run(args: argparse.Namespace) -> int:
    from app.framework import bundle
    from app.framework.runtime import configure_threads

    configure_threads()  # TACTILE_TORCH_THREADS, else one thread (see app.framework.runtime)
    if args.top_k < 1:
        raise ValueError(f"--top-k must be at least 1, got {args.top_k}")
    if args.lines:
        if args.objects is not None:
            raise ValueError('--objects labels one request; with --lines give each line "objects"')
        if args.samples == "-":
            return answer_lines(args.model, sys.stdin, sys.stdout, args.top_k)
        with open(args.samples) as lines:
            return answer_lines(args.model, lines, sys.stdout, args.top_k)
    model = bundle.load(args.model)
    request = with_objects(read_samples(args.samples), args.objects)
    print(json.dumps({"method": model.method, "results": results(model, request, args.top_k)}))
    return 0


def answer_lines(model_file: Path, lines: Iterable[str], out: TextIO, top_k: int) -> int:
    """Answer each JSON line of ``lines`` with one JSON line on ``out``, flushed at once.

    The model file must load at the start. When it changes later (a sync replaces it by a
    rename) it is read again; if the new file cannot be read, the answers go on with the
    model read before and carry a ``warning`` until a readable file replaces it."""
    from app.framework import bundle

    source = bundle.BundleFile(model_file)
    model, _ = source.load()
    warning = None
    for line in lines:
        if not line.strip():
            continue
        try:
            model, fresh = source.load()
            warning = None if fresh else warning
        except (ValueError, OSError) as exc:
            warning = (
                f"the model file changed and cannot be read ({exc}); "
                "answering with the one read before"
            )
        try:
            answer = {
                "method": model.method,
                "results": results(model, _from_json(line, "the line"), top_k),
            }
        except ValueError as exc:  # the framework's errors name the problem
            answer = {"error": str(exc)}
        out.write(json.dumps({**answer, **({"warning": warning} if warning else {})}) + "\n")
        out.flush()
    return 0
