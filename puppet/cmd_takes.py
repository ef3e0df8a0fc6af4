"""`puppet takes`: the take library (list, search, show, tag, note, import a folder, check)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "takes",
        help="the take library: list, search, show, tag, note, import FOLDER, check",
        description="Every take recorded with `puppet live --record` is registered in the take library (one "
        "SQLite file in your data folder, or --library PATH) when its recording starts, and completed when it "
        "ends. Search words match names, performers, notes, tags, markers, expressions and devices; filters: "
        "performer:NAME tag:T expression:E date:2026-12-03 (or date:2026-12) after:DATE before:DATE missing:yes "
        "face:NAME state:crashed|damaged|recording. `check` finds moved takes again by their content, completes "
        "takes whose show died, marks takes whose file no longer holds them, and adds thumbnails and expression "
        "spans. See docs/studio.md.",
    )
    p.add_argument("--library", metavar="PATH", help="the library file (default: your data folder)")
    sub = p.add_subparsers(dest="takes_command", metavar="ACTION", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--library", metavar="PATH", default=argparse.SUPPRESS, help="the library file")
    common.add_argument("--json", action="store_true", help="machine-readable output")
    sub.add_parser("list", parents=[common], help="every take")
    s = sub.add_parser("search", parents=[common], help="takes matching a query")
    s.add_argument("query", metavar="QUERY", help='e.g. "smile performer:ana after:2026-12-01"')
    s = sub.add_parser("show", parents=[common], help="everything about one take")
    s.add_argument("id", type=int, metavar="ID")
    s.add_argument("--thumbnail", metavar="FILE.png", help="write the take's thumbnail here")
    s = sub.add_parser("tag", parents=[common], help="tag a take")
    s.add_argument("id", type=int, metavar="ID")
    s.add_argument("tag", metavar="TAG")
    s.add_argument("--remove", action="store_true", help="remove the tag instead")
    s = sub.add_parser("note", parents=[common], help="set a take's note")
    s.add_argument("id", type=int, metavar="ID")
    s.add_argument("text", metavar="TEXT")
    s = sub.add_parser("import", parents=[common], help="register every recording under a folder (or one recording)")
    s.add_argument("folder", metavar="FOLDER|FILE")
    s.add_argument("--performer", metavar="NAME", help="performer of takes that do not name one")
    s = sub.add_parser("check", parents=[common],
                       help="find moved or deleted takes, complete takes whose show died, mark takes "
                       "whose file no longer holds them; add thumbnails and expression spans")
    s.add_argument("--in", dest="roots", action="append", default=[], metavar="FOLDER",
                   help="also look here for moved takes; repeatable")
    s.add_argument("--no-analyse", action="store_true", help="skip thumbnails and expression spans")
    p.set_defaults(func=run)


#: how the listing flags a take's state (a complete take: nothing)
STATES = {
    "recording": "  [recording]",
    "died": "  [its show died: `puppet takes check` completes it]",
    "crashed": "  [ended by a crash]",
    "damaged": "  [damaged: no longer a take]",
}
#: the same, said in full by `takes show`
STATE_TEXT = {
    "complete": "complete",
    "recording": "being recorded by a show",
    "died": "its show died while recording; `puppet takes check` completes this entry from the file",
    "crashed": "ended by a crash; read up to its last whole tick",
    "damaged": "damaged: the file no longer holds this take (details kept from before)",
}


def _cells(t: dict[str, Any]) -> tuple[str, str, str]:
    """The listing's variable-width cells: performer, tags, expressions."""
    tags = ",".join(t["tags"]) or "-"
    exprs = ",".join(sorted({e["expression"] for e in t["expressions"]} - {"neutral"})) or "-"
    return t["performer"] or "-", tags, exprs


def _line(t: dict[str, Any], widths: tuple[int, int, int] = (12, 16, 20)) -> str:
    date = (t["recorded"] or "")[:16].replace("T", " ")
    flag = "  [missing]" if t["missing"] else STATES.get(t["state"], "")
    cells = "  ".join(f"{c:<{w}}" for c, w in zip(_cells(t), widths))
    return f"{t['id']:>5}  {date:<16}  {t['duration']:7.2f} s  {cells}  {t['path']}{flag}"


def _public(t: dict[str, Any]) -> dict[str, Any]:
    d = dict(t)
    d["thumbnail"] = bool(d.get("thumbnail"))
    return d


def _listing(rows: list[dict[str, Any]], as_json: bool) -> None:
    if as_json:
        print(json.dumps([_public(t) for t in rows]))
        return
    if not rows:
        print("puppet: no takes")
        return
    # columns as wide as their widest cell, so the paths line up however many expressions a take has
    widths = tuple(max([w] + [len(c[k]) for c in map(_cells, rows)]) for k, w in enumerate((12, 16, 20)))
    heads = "  ".join(f"{h:<{w}}" for h, w in zip(("performer", "tags", "expressions"), widths))
    print(f"{'id':>5}  {'recorded (UTC)':<16}  {'length':>9}  {heads}  path")
    for t in rows:
        print(_line(t, widths))  # type: ignore[arg-type]  # three widths


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from puppet.errors import PuppetError
    from puppet.library import complete_died, library_path, open_library
    from puppet.library.upkeep import check, import_folder

    path = library_path(args.library)
    act = args.takes_command
    if path is not None and act != "import" and not path.exists() and not Path(f"{path}.journal").exists():
        # no library there yet (a new name, or a mistyped one): nothing to read, and nothing is made
        if act in ("list", "search", "check"):
            if getattr(args, "json", False) and act != "check":
                print("[]")
            else:
                print(f"puppet: no takes (no take library at {path} yet: `puppet takes import FOLDER` or a "
                      "recorded show starts it)")
            return 0
        raise PuppetError(f"no take {args.id}: there is no take library at {path} (see `puppet takes list`)")
    with open_library(args.library) as lib:
        if act in ("list", "search", "show"):
            complete_died(lib, lambda s: print(f"puppet: {s}", file=sys.stderr))
        if act == "list":
            _listing(lib.search(""), args.json)
        elif act == "search":
            _listing(lib.search(args.query), args.json)
        elif act == "show":
            t = lib.get(args.id)
            if args.thumbnail:
                if not t["thumbnail"]:
                    raise PuppetError(f"take {args.id} has no thumbnail yet; `puppet takes check` makes it")
                from safefile import atomic_write

                with atomic_write(Path(args.thumbnail), "wb") as fh:
                    fh.write(t["thumbnail"])
            if args.json:
                print(json.dumps(_public(t)))
                return 0
            for key in ("id", "path", "hash", "recorded", "registered", "duration", "ticks", "tick_rate", "face",
                        "identity", "resolution", "program", "performer", "notes"):
                val = t[key]
                print(f"{key:>11}: {val if val not in (None, '') else '-'}")
            print(f"{'devices':>11}: {', '.join(t['devices']) or '-'}")
            print(f"{'tags':>11}: {', '.join(t['tags']) or '-'}")
            print(f"{'markers':>11}: " + (", ".join(f"{m[1]} at {m[0]:.2f} s" for m in t["markers"]) or "-"))
            print(f"{'thumbnail':>11}: " + (f"{len(t['thumbnail'])} bytes" if t["thumbnail"] else "not yet (takes check)"))
            print(f"{'state':>11}: " + ("missing (not found by the last check)" if t["missing"]
                                        else STATE_TEXT.get(t["state"], t["state"])))
            if t["expressions"]:
                print(f"{'expressions':>11}:")
                for e in t["expressions"]:
                    print(f"{'':>13}{e['start']:7.2f} s .. {e['end']:7.2f} s  {e['expression']:<10} {e['score']:.2f}")
            else:
                print(f"{'expressions':>11}: " + ("none found" if t["analysed"] else "not yet (takes check)"))
        elif act == "tag":
            lib.tag(args.id, args.tag, remove=args.remove)
            print(f"puppet: take {args.id} tags: {', '.join(lib.get(args.id)['tags']) or '-'}")
        elif act == "note":
            lib.note(args.id, args.text)
            print(f"puppet: take {args.id} note set")
        elif act == "import":
            rep = import_folder(lib, args.folder, args.performer)
            for why in rep.skipped[:5]:
                print(f"puppet: skipped {why}", file=sys.stderr)
            if len(rep.skipped) > 5:
                print(f"puppet: ... and {len(rep.skipped) - 5} more files skipped", file=sys.stderr)
            n = len(rep.registered)
            print(f"puppet: registered {n} take{'' if n == 1 else 's'} from {args.folder}"
                  + (f" ({len(rep.skipped)} files were not recordings)" if len(rep.skipped) > 1
                     else " (1 file was not a recording)" if rep.skipped else "")
                  + (f"; {len(rep.known)} already in the library, unchanged" if rep.known else "")
                  + ("; `puppet takes check` adds their thumbnails and expression spans" if n else ""))
        elif act == "check":
            for r in args.roots:
                if not Path(r).is_dir():
                    raise PuppetError(f"{r}: not a folder (--in names a folder to look for moved takes in)")
            rep = check(lib, [Path(r) for r in args.roots], analyse=not args.no_analyse,
                        progress=lambda s: print(f"puppet: {s}", file=sys.stderr))
            for i, where in rep.found:
                print(f"puppet: take {i} moved: found again at {where}")
            for i in rep.missing:
                print(f"puppet: take {i} is missing: {lib.get(i)['path']}")
            for i in rep.changed:
                t = lib.get(i)
                print(f"puppet: take {i} changed: {t['path']} holds another take now; its entry was re-read from it "
                      f"({t['duration']:.2f} s; thumbnail and expressions made again)")
            for i in rep.crashed:
                t = lib.get(i)
                print(f"puppet: take {i} ended by a crash: completed from {t['path']} ({t['duration']:.2f} s, "
                      f"up to its last whole tick)")
            for i, why in rep.damaged:
                print(f"puppet: take {i} is damaged: {why}; its entry keeps the take's details and is marked "
                      "damaged (restore the file, or `puppet takes check --in FOLDER` where a copy is)")
            for i in rep.recording:
                print(f"puppet: take {i} is being recorded by a show: left as it is")
            for why in rep.failed[:5]:
                print(f"puppet: {why}", file=sys.stderr)
            print(f"puppet: checked {rep.checked} takes: {rep.ok} in place, {len(rep.changed)} changed and "
                  f"re-read, {len(rep.found)} found again, {len(rep.missing)} missing, {len(rep.crashed)} "
                  f"completed after a crash, {len(rep.damaged)} damaged, {len(rep.recording)} being recorded; "
                  f"analysed {len(rep.analysed)}")
            if args.json:
                print(json.dumps({"ok": rep.ok, "changed": rep.changed, "found": rep.found,
                                  "missing": rep.missing, "analysed": rep.analysed, "crashed": rep.crashed,
                                  "damaged": [i for i, _ in rep.damaged], "recording": rep.recording}))
    return 0
