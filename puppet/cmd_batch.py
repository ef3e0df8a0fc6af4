"""`puppet batch`: export, fit or recognize many takes at once, on every core or on a Dask farm."""

from __future__ import annotations

import argparse
import os
import sys

#: The local cluster's largest size: worker processes a core (more only queue for the CPU).
MAX_WORKERS_PER_CORE = 4


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from puppet.cmd_replay import _size

    p = subparsers.add_parser(
        "batch",
        help="export, fit or recognize many takes at once (every core, or a Dask farm with --scheduler)",
        description="SELECTION: take files, folders of them, or a take-library query (e.g. 'performer:ana "
        "tag:keeper'). One task per take; a long video is rendered in chunks in parallel and encoded once. "
        "Outputs equal the single commands' (`puppet replay --out`, `puppet fit`, `puppet recognize --json`), "
        "are written whole or not at all, and are skipped on a re-run when their inputs did not change. "
        "Without --scheduler a local cluster of one worker process per core starts on 127.0.0.1. "
        "See docs/studio.md.",
    )
    sub = p.add_subparsers(dest="batch_command", metavar="ACTION", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("selection", nargs="+", metavar="SELECTION", help="files, folders or a library query")
    common.add_argument("--out", required=True, metavar="DIR", help="the folder the outputs go to")
    common.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running `dask scheduler` (a farm)")
    common.add_argument("--workers", type=int, metavar="N", help="local cluster size (default: one per core)")
    common.add_argument("--library", metavar="PATH", help="the take library a query searches")
    common.add_argument("--force", action="store_true", help="redo outputs that are up to date")
    common.add_argument("--rig", metavar="R", help="fit/recognize: rig file (on every worker)")
    common.add_argument("--fps", type=float, metavar="N",
                        help="export: frame rate (default 30 for video, the tick rate for data); fit/recognize: "
                        "frame rate of PC2 samples / ARKit timecodes")
    e = sub.add_parser("export", parents=[common], help="as `puppet replay TAKE --out FILE`, for many takes")
    e.add_argument("--to", default="mp4,pc2,csv", metavar="KINDS",
                   help="comma-separated: mp4, pc2 (+ obj), csv, arkit, curves (default mp4,pc2,csv)")
    e.add_argument("--view", metavar="V", help="video view (as puppet replay; default shaded)")
    e.add_argument("--size", type=_size, metavar="WxH", help="video size (default 1280x720)")
    e.add_argument("--supersample", type=int, metavar="N", help="video: N x N samples per pixel (default 1)")
    e.add_argument("--crf", type=int, metavar="Q", help="video: H.264 quality (default as puppet replay)")
    e.add_argument("--chunk-frames", type=int, default=1800, metavar="N",
                   help="split videos longer than N frames into chunks rendered in parallel (0: never)")
    f = sub.add_parser("fit", parents=[common], help="as `puppet fit INPUT --out TAKE.jsonl`, for many captures")
    f.add_argument("--map", metavar="CORR.json", help="correspondence file (on every worker)")
    r = sub.add_parser("recognize", parents=[common], help="as `puppet recognize INPUT --json`, for many inputs")
    r.add_argument("--map", metavar="CORR.json", help="correspondence file (on every worker)")
    p.set_defaults(func=run, exit_at_once=True)  # `puppet.cli.exit_at_once`: Dask's teardown skipped


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from puppet.batch.plan import EXPORT_KINDS
    from puppet.batch.run import run as run_batch
    from puppet.errors import PuppetError, not_applying

    action = args.batch_command
    note = ""  # said with the batch's result: a batch that cannot start stays one line
    kinds: list[str] = []
    opts: dict = {"fps": args.fps}
    if args.workers is not None and args.workers < 1:
        raise PuppetError("--workers must be at least 1")
    most = MAX_WORKERS_PER_CORE * max(1, os.cpu_count() or 1)
    if args.workers is not None and args.workers > most and args.scheduler is None:
        # each is a process of its own: --workers 100000 started processes until the machine choked
        raise PuppetError(f"--workers {args.workers}: at most {most} on this machine ({MAX_WORKERS_PER_CORE} a core); "
                          "a farm of more machines is joined with --scheduler")
    if getattr(args, "chunk_frames", 0) < 0:
        raise PuppetError(f"--chunk-frames must be 0 (never split) or a number of frames, got {args.chunk_frames}")
    if action == "export":
        kinds = [k.strip().lower() for k in args.to.split(",") if k.strip()]
        bad = [k for k in kinds if k not in EXPORT_KINDS]
        if bad or not kinds:
            raise PuppetError(f"--to takes {', '.join(EXPORT_KINDS)}; got {args.to!r}")
        unused = [f"--{name}" for name in ("view", "size", "supersample", "crf") if getattr(args, name) is not None]
        if "mp4" not in kinds:  # as `puppet replay`: dropped without a word before
            note = not_applying(unused, f"--to {','.join(kinds)} (only mp4 is drawn)")
        args.view = "shaded" if args.view is None else args.view
        args.size = (1280, 720) if args.size is None else args.size
        args.supersample = 1 if args.supersample is None else args.supersample
        if "mp4" in kinds:  # the renderer's import (~1 s) only where a view is drawn
            from render.renderer import VIEWS
        else:
            VIEWS = (args.view,)
        if args.view not in VIEWS:
            raise PuppetError(f"unknown view {args.view!r}; choose one of {', '.join(VIEWS)}")
        if not 1 <= args.supersample <= 4 or (args.crf is not None and not 0 <= args.crf <= 51):
            raise PuppetError("--supersample takes 1 to 4, --crf 0 to 51")
        opts.update(view=args.view, size=list(args.size), supersample=args.supersample, crf=args.crf)
    else:
        opts.update(rig=args.rig, map=args.map)
    if args.scheduler is not None:
        args.scheduler = scheduler_address(args.scheduler)
    out = Path(args.out)
    rep = run_batch(action, args.selection, out, kinds=kinds, opts=opts, scheduler=args.scheduler,
                    workers=args.workers, chunk_frames=getattr(args, "chunk_frames", 0), library=args.library,
                    force=args.force)
    for text in [*rep.warnings, *([note] if note else [])]:
        print(text, file=sys.stderr)
    for origin, why in rep.failed.items():
        print(f"puppet: failed: {why}", file=sys.stderr)
    done = len({p.name for p in rep.written})
    print(f"puppet: batch {action}: wrote {_count(done, 'file')} to {out}"
          + (f" on {_count(rep.workers, 'worker')} ({_count(rep.tasks, 'task')})" if rep.tasks else "")
          + (f"; {len(rep.skipped)} outputs up to date, skipped" if rep.skipped else "")
          + (f"; expressions stored for {rep.library_takes} library takes" if rep.library_takes else "")
          + (f"; {_count(len(rep.failed), 'input')} failed" if rep.failed else ""))
    return 2 if rep.failed else 0


def _count(n: int, thing: str) -> str:
    return f"{n} {thing}{'' if n == 1 else 's'}"


def scheduler_address(text: str) -> str:
    """`--scheduler`: tcp://HOST:PORT (or tls://, or HOST:PORT, taken as tcp://), checked before
    anything is done: Dask's own parser raises a traceback on `foo`, and a batch with nothing to do
    never connected, so a mistyped address passed unnoticed."""
    from urllib.parse import urlsplit

    from puppet.errors import PuppetError

    bad = PuppetError(f"--scheduler {text!r}: expected tcp://HOST:PORT, the address `dask scheduler` prints")
    given = text.strip()
    try:  # urlsplit itself refuses an unclosed IPv6 bracket (tcp://[::1) with a ValueError
        url = urlsplit(given if "://" in given else "tcp://" + given)
        port = url.port
    except ValueError:
        raise bad from None
    if url.scheme not in ("tcp", "tls") or not url.hostname or port is None or not 0 < port < 65536 \
            or url.path not in ("", "/") or url.query or url.username:
        raise bad
    return f"{url.scheme}://{url.netloc}"
