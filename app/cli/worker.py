"""``tactile-zsl worker``: the retraining worker as its own process."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "worker",
        help="run the retraining worker",
        description="Fold enrollments (novel classes, one-shot samples) into new model versions "
        "and activate them. Shares the store named by TACTILE_DATABASE_URL / TACTILE_DATA_DIR "
        "with 'tactile-zsl serve --no-worker'. Stops cleanly on SIGTERM or Ctrl-C.",
    )
    p.add_argument("--data-dir", help="folder for the SQLite store (TACTILE_DATA_DIR)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import signal
    import threading

    from app.config import Settings
    from app.framework.runtime import configure_threads
    from app.server.logs import configure_logging
    from worker import run_worker

    settings = Settings(**({"data_dir": args.data_dir} if args.data_dir else {}))
    configure_threads(settings.torch_threads)  # as every serve and worker process does
    configure_logging()  # serve's format; faiss's loader quiet
    stop = threading.Event()
    # finish the round in progress, then leave; a kill instead leaves jobs for re-queueing
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    run_worker(settings, stop)
    return 0
