"""``tactile-zsl``: one console script, one module per sub-command.

Each sub-command module defines ``register(subparsers)``, which adds its parser
and sets ``handler``; heavy imports happen inside handlers so ``--help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = [
    "train",
    "evaluate",
    "recognize",
    "serve",
    "worker",
    "apikey",
    "store",
    "model",
    "dataset",
    "ros2",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tactile-zsl",
        description="Tactile recognition of known and novel objects: train, evaluate, serve.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"app.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (ValueError, OSError) as exc:  # library errors name the problem; no traceback
        print(f"tactile-zsl {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
