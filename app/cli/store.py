"""``tactile-zsl store``: check, back up and restore the store."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "store",
        help="check, back up or restore the store",
        description="The store named by TACTILE_DATABASE_URL / TACTILE_DATA_DIR holds every class, "
        "sample and model version. 'check' runs the integrity checks (SQLite or PostgreSQL). "
        "'backup' copies a SQLite store while the service runs; 'restore' puts a backup back "
        "(refused while an API process or worker has the store open). For PostgreSQL use "
        "pg_dump / pg_restore.",
    )
    p.add_argument("--data-dir", help="folder for the SQLite store (TACTILE_DATA_DIR)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    actions.add_parser("check", help="integrity checks; exit status 1 if a problem is found")
    backup = actions.add_parser("backup", help="copy the SQLite store, online, to a new file")
    backup.add_argument("out", type=Path, help="the backup file to write (must not exist)")
    restore = actions.add_parser("restore", help="replace the SQLite store by a checked backup")
    restore.add_argument("backup", type=Path, help="a file written by 'store backup'")
    restore.add_argument(
        "--replace", action="store_true", help="overwrite a store that holds data already"
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.config import Settings
    from app.store import backup
    from app.store.integrity import check_store

    settings = Settings(**({"data_dir": args.data_dir} if args.data_dir else {}))
    url = settings.sqlalchemy_url
    if args.action == "check":
        problems = check_store(url)
        for problem in problems:
            print(f"problem: {problem}")
        print(f"{len(problems)} problems found" if problems else "the store passes every check")
        return 1 if problems else 0
    if args.action == "backup":
        summary = backup.backup(url, args.out)
        print(f"backed up {summary} to {args.out}")
    else:
        summary = backup.restore(args.backup, url, replace=args.replace)
        print(f"restored {summary} from {args.backup}")
    return 0
