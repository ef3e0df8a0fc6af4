"""``puppet channels``: every channel of the face with its kind, muscle type, AUs and range.

``--json`` prints one JSON list of objects {name, kind, muscle_type, aus, lo, hi, default, doc};
outside tools rely on at least ``name``.
"""

from __future__ import annotations

import argparse
import json
from typing import Any


def register(subparsers: Any) -> None:
    """Add the ``channels`` subcommand."""
    p = subparsers.add_parser("channels", help="list the face's channels",
                              description="List every channel with its type, FACS AUs and range.")
    p.add_argument("--json", action="store_true", help="a JSON list of channel objects")
    p.set_defaults(func=run)


def channel_rows() -> list[dict[str, Any]]:
    """The channel list as plain dicts, in channel order."""
    from sim.channels import CHANNEL_SPECS

    return [
        {"name": s.name, "kind": s.kind, "muscle_type": s.muscle_type, "aus": list(s.aus),
         "lo": s.lo, "hi": s.hi, "default": s.default, "doc": s.doc}
        for s in CHANNEL_SPECS
    ]


def run(args: argparse.Namespace) -> int:
    """Print the channels."""
    rows = channel_rows()
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        kind = r["muscle_type"] or r["kind"]
        aus = "+".join(r["aus"]) or "-"
        print(f"{r['name']:<{width}}  {kind:<9}  {aus:<15} {r['lo']:g}..{r['hi']:g} "
              f"(default {r['default']:g})  {r['doc']}")
    return 0
