"""``tactile-zsl model choose``: ask method auto to choose again, as
``POST /v1/models/choice`` does, on the store the settings name."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "model",
        help="ask method auto to choose its method again",
        description="'choose' queues a choose_method job in the store named by "
        "TACTILE_DATABASE_URL / TACTILE_DATA_DIR: the worker's next round fits method auto "
        "anew (a probe of every stored sample, then the winner), where refits otherwise keep "
        "the method chosen before. Exit status 2 where TACTILE_METHOD is not auto.",
    )
    p.add_argument("--data-dir", help="folder for the SQLite store (TACTILE_DATA_DIR)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    actions.add_parser("choose", help="queue a new choice of method; prints the job's id")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.config import Settings
    from app.service.method_choice import ask_for_choice
    from app.store import migrate
    from app.store.db import make_engine, make_sessionmaker

    settings = Settings(**({"data_dir": args.data_dir} if args.data_dir else {}))
    engine = make_engine(settings.sqlalchemy_url)
    migrate.upgrade(engine)
    with make_sessionmaker(engine).begin() as s:
        job = ask_for_choice(s, settings.method, requested_by="cli")
        s.flush()
        job_id = job.id
    print(f"job {job_id} queued: the worker's next round chooses the method again")
    return 0
