"""``radar-io token``: named tokens with roles in the tokens file (hashes only)."""

from __future__ import annotations

import argparse
import sys
from typing import Any


def add_subparser(sub: Any) -> None:
    p = sub.add_parser("token", help="add, list or revoke named tokens with roles",
                       description="Manage the tokens file the service reads (tokens_file): "
                       "each token has a name and a role (viewer, operator, admin); the file "
                       "holds only scrypt hashes.")
    p.add_argument("--tokens-file", required=True, metavar="FILE",
                   help="the tokens file (created by the first add)")
    acts = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    a = acts.add_parser("add", help="a new token: printed alone on stdout, once")
    a.add_argument("name")
    a.add_argument("--role", required=True, choices=("viewer", "operator", "admin"))
    acts.add_parser("list", help="names, roles and creation times (never the tokens)")
    r = acts.add_parser("revoke", help="remove a token (the service drops it within 1 s)")
    r.add_argument("name")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from radar_io.service.auth import TokensFile

    f = TokensFile(args.tokens_file)
    if args.action == "add":
        token = f.add(args.name, args.role)
        print(token, flush=True)
        print(f"token {args.name!r} ({args.role}) added to {f.path}; it is shown only now",
              file=sys.stderr)
    elif args.action == "list":
        for e in f.entries():
            print(f"{e['name']}\t{e['role']}\t{e.get('created_utc', '')}")
    else:
        if not f.revoke(args.name):
            print(f"radar-io: error: no token named {args.name!r} in {f.path}", file=sys.stderr)
            return 2
        print(f"token {args.name!r} revoked", file=sys.stderr)
    return 0
