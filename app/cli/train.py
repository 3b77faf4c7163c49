"""``tactile-zsl train``: fit a recognizer on a dataset and write a model bundle."""

from __future__ import annotations

import argparse
import json
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train a base model and write a bundle",
        description="Train the known-class model (encoder + FC_Y, GMM novelty detector with its "
        "threshold tuned on validation objects, generator G with Algorithms 1 and 2) on every "
        "class of a dataset, and write a versioned model bundle.",
    )
    p.add_argument(
        "--dataset",
        default="simulated",
        help="'simulated', 'simulated:N' (N objects), 'phac2:PATH', 'folder:DIR' or "
        "'biotac:DIR' (raw BioTac trials: the model fits its tactile-image featurizer on them, "
        "keeps it in the bundle and recognises raw trials) (default: simulated)",
    )
    p.add_argument(
        "--out", required=True, help="path of the model bundle to write (written atomically)"
    )
    p.add_argument(
        "--method",
        default=None,
        help="recognition method (default: the service's default method); see 'evaluate --help'",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="random seed for data simulation and training (default 0)",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="method hyper-parameter, e.g. --param encoder_epochs=30 "
        "(repeatable; value parsed as JSON)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(handler=run)


def parse_params(items: list[str]) -> dict:
    params = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--param expects NAME=VALUE, got {item!r}")
        try:
            params[name] = json.loads(value)
        except json.JSONDecodeError:
            params[name] = value
    return params


def run(args: argparse.Namespace) -> int:
    from app.data.biotac import BioTacDataset
    from app.data.sources import open_dataset
    from app.framework import bundle
    from app.framework.registry import DEFAULT_METHOD, make_method
    from app.framework.runtime import configure_threads

    configure_threads()  # TACTILE_TORCH_THREADS, else one thread (see app.framework.runtime)
    dataset = open_dataset(args.dataset, seed=args.seed)
    params = {"seed": args.seed, **parse_params(args.param)}
    try:
        model = make_method(args.method or DEFAULT_METHOD, **params)
    except TypeError as exc:
        raise ValueError(f"bad --param: {exc}") from None
    model._validate_params()  # fit checks them too; a bad value is refused before any work
    what = (
        f"{len(dataset)} raw trials"
        if isinstance(dataset, BioTacDataset)
        else f"{len(dataset)} samples, input {dataset.input_shape}"
    )
    print(
        f"training '{model.method}' on {dataset.name}: {what}, {dataset.n_classes} classes",
        file=sys.stderr,
    )
    # "auto" fits the method its probe chooses and returns that method's model
    model = model.fit(dataset, progress=not args.quiet)
    digest = bundle.save(model, args.out)
    summary = {k: v for k, v in model.metrics.items() if k != "params"}
    print(json.dumps({"bundle": args.out, "sha256": digest, "metrics": summary}, indent=2))
    return 0
