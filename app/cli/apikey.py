"""``tactile-zsl apikey``: create, list and revoke the API keys of the store."""

from __future__ import annotations

import argparse

SCOPES = ("read", "enroll", "admin")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "apikey",
        help="manage API keys",
        description="API keys for the X-API-Key header, stored hashed in the store named by "
        "TACTILE_DATABASE_URL / TACTILE_DATA_DIR. Once any key exists, every /v1 request needs "
        "one. Scopes: read (GETs and recognize), enroll (also register classes and add "
        "samples), admin (also activate and roll back models).",
    )
    p.add_argument("--data-dir", help="folder for the SQLite store (TACTILE_DATA_DIR)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    create = actions.add_parser(
        "create",
        help="create a key; it is printed once, alone on the last line",
        description="Create a key. The key is printed once, alone on the last line of the "
        "output; only its SHA-256 is stored, so it cannot be shown again.",
    )
    create.add_argument("--scope", required=True, choices=SCOPES)
    create.add_argument("--name", help="a label to tell keys apart (e.g. the robot's name)")
    actions.add_parser("list", help="list keys (id, prefix, scope, name, created, revoked)")
    revoke = actions.add_parser("revoke", help="revoke a key by its id (see 'list')")
    revoke.add_argument("id", type=int)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.config import Settings
    from app.store import migrate, repo
    from app.store.db import make_engine, make_sessionmaker

    settings = Settings(**({"data_dir": args.data_dir} if args.data_dir else {}))
    engine = make_engine(settings.sqlalchemy_url, settings.db_timeout_seconds)
    try:
        migrate.upgrade(engine)  # a key may be made before the first serve
        with make_sessionmaker(engine).begin() as s:
            if args.action == "create":
                key, row = repo.create_api_key(s, args.scope, args.name)
                print(
                    f"created API key {row.id} ({row.prefix}…) with scope '{row.scope}'; "
                    "it is shown once, now:"
                )
                print(key)
            elif args.action == "list":
                for row in repo.list_api_keys(s):
                    revoked = row.revoked_at.isoformat() if row.revoked_at else "-"
                    print(
                        f"{row.id}\t{row.prefix}…\t{row.scope}\t{row.name or '-'}\t"
                        f"{row.created_at.isoformat()}\trevoked: {revoked}"
                    )
            elif not repo.revoke_api_key(s, args.id):
                raise ValueError(f"no active API key with id {args.id}")
            else:
                print(f"revoked API key {args.id}")
    finally:
        engine.dispose()
    return 0
