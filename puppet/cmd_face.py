"""``puppet face``: the scanned head's saved identities (characters).

    puppet face save NAME --identity SEED|w1,w2,... [--replace]   save an identity; use it with --face NAME
    puppet face list [--json]                        the saved identities
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from puppet.errors import PuppetError


def register(subparsers: Any) -> None:
    """Add the ``face`` subcommand."""
    p = subparsers.add_parser("face", help="save and list identities of the scanned head (--face NAME)",
                              description="Characters of the scanned head: identity weights saved by name.")
    sub = p.add_subparsers(dest="face_command", metavar="ACTION")
    s = sub.add_parser("save", help="save an identity under a name")
    s.add_argument("name", metavar="NAME")
    s.add_argument("--identity", required=True, metavar="SEED|w1,w2,...",
                   help="a seed (weights drawn from N(0, 1), reproducible) or up to 100 weights")
    s.add_argument("--replace", action="store_true",
                   help="replace a saved identity of that name with other weights (else it is kept and this says so)")
    s.set_defaults(func=_save)
    ls = sub.add_parser("list", help="the saved identities")
    ls.add_argument("--json", action="store_true", help="machine-readable output")
    ls.set_defaults(func=_list)
    p.set_defaults(func=lambda args: (p.print_help(), 0)[1])


def _save(args: argparse.Namespace) -> int:
    from puppet.faces import parse_identity, save_identity

    try:
        weights, seed = parse_identity(args.identity)
    except ValueError as err:
        raise PuppetError(str(err)) from err
    from puppet.faces import check_saved, identity_path

    old = identity_path(args.name)
    if not args.replace and (old.exists() or old.is_symlink()):
        check_saved(args.name, old, tuple(weights), seed)
    path = save_identity(args.name, weights, seed, replace=args.replace)
    print(f"saved identity {args.name} to {path}; use it with --face {args.name}")
    return 0


def _list(args: argparse.Namespace) -> int:
    from puppet.faces import data_dir, list_identities

    rows = list_identities()
    bad = [r for r in rows if r[3]]
    if args.json:
        print(json.dumps([{"name": n, "seed": s, "identity": list(w) if w else None, "error": e or None}
                          for n, w, s, e in rows]))
    elif not rows:
        print(f"no saved identities in {data_dir()} (save one with `puppet face save NAME --identity SEED`)")
    else:
        for name, w, seed, err in rows:
            if not err:
                first = ", ".join(f"{x:.2f}" for x in (w or ())[:3])
                what = f"seed {seed}" if seed is not None else f"weights {first}, ..."
                print(f"{name:<20} {what}")
    for _, _, _, err in bad:
        print(f"puppet: error: {err}", file=sys.stderr)
    return 2 if bad else 0
