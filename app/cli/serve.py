"""``tactile-zsl serve``: the HTTP API (and, by default, the retraining worker)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="run the recognition service",
        description="Serve the REST API. On first start (empty store) trains the base model from "
        "the dataset and stores it as model version 1. Settings come from TACTILE_* environment "
        "variables; these options override them.",
    )
    p.add_argument("--host", help="interface to listen on (TACTILE_HOST, default 127.0.0.1)")
    p.add_argument("--port", type=int, help="port to listen on (TACTILE_PORT, default 8000)")
    p.add_argument(
        "--processes",
        type=int,
        help="API processes on the port (TACTILE_PROCESSES; default one per CPU core, at most 4)",
    )
    p.add_argument(
        "--dataset",
        help="bootstrap data: simulated, simulated:N, phac2:PATH, folder:DIR, biotac:DIR, or "
        "none to start without classes or attributes (TACTILE_DATASET, default simulated)",
    )
    p.add_argument(
        "--model",
        help="a model bundle trained on --dataset ('tactile-zsl train'), stored as the first "
        "model instead of training on first start (TACTILE_BASE_MODEL)",
    )
    p.add_argument("--data-dir", help="folder for the SQLite store (TACTILE_DATA_DIR)")
    p.add_argument(
        "--no-worker",
        action="store_true",
        help="do not run the retraining worker in this process (run 'tactile-zsl worker')",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.api.main import create_app
    from app.config import Settings
    from app.server import processes
    from app.server.http_protocol import CoalescingHttpToolsProtocol
    from app.server.logs import configure_logging
    from app.service.bootstrap import ensure_ready
    from app.store.db import make_engine, make_sessionmaker

    overrides = {
        "host": args.host,
        "port": args.port,
        "processes": args.processes,
        "dataset": args.dataset,
        "base_model": args.model,
        "data_dir": args.data_dir,
        "embedded_worker": False if args.no_worker else None,
    }
    overrides = {k: v for k, v in overrides.items() if v is not None}
    settings = Settings(**overrides)
    configure_logging()
    # migrate and bootstrap before the server starts, so a bad dataset or an unreachable
    # database is a one-line error here rather than a failed ASGI startup
    engine = make_engine(settings.sqlalchemy_url, settings.db_timeout_seconds)
    try:
        ensure_ready(settings, engine, make_sessionmaker(engine))
    finally:
        engine.dispose()
    _give_back_freed_memory()
    server = {
        "log_level": "info",
        "access_log": settings.access_log,
        "http": CoalescingHttpToolsProtocol,
    }
    n = settings.api_processes if processes.supported() else 1
    port = settings.port or processes.free_port(settings.host)  # one port for all of them
    # said once the model is loaded and every process listens: when /readyz answers ready
    ready = (
        f"serving on http://{settings.host}:{port} with {n} API process{'' if n == 1 else 'es'}; "
        f"API docs at http://{settings.host}:{port}/docs"
    )
    if n == 1:
        app = create_app(settings)
        config = uvicorn.Config(app, host=settings.host, port=port, **server)
        processes.AnnouncingServer(config, ready).run()
        return 0
    return processes.serve({**overrides, "port": port}, n, server, ready)


def _give_back_freed_memory() -> None:
    """Return the heap's free pages to the system after the bootstrap (glibc's
    ``malloc_trim``; elsewhere nothing). Training or storing the first model frees its
    arrays, but glibc keeps freed heap pages mapped: this process, which only supervises
    the API processes from then on (or is the one API process), held 1.24 GB after storing
    a 3,000-object model where its API processes held 1.39 GB each."""
    import ctypes
    import gc

    gc.collect()
    try:
        trim = ctypes.CDLL(None).malloc_trim  # the C library this process runs on
    except (OSError, TypeError, AttributeError):  # not glibc: nothing to trim
        return
    trim(0)
