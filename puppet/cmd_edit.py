"""`puppet edit TAKE.jsonl`: the force-graph editor in the browser (see docs/panel.md)."""

from __future__ import annotations

import argparse
import sys


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "edit",
        help="edit a take's channels as force graphs in the browser (curves layered over the take)",
        description="Serve the force-graph editor for a take and print its URL. Edits are saved as "
        "curves beside the take (TAKE.curves, version 2); the take itself is never written. "
        "Play the result with `puppet replay TAKE.jsonl --curves TAKE.curves`. See docs/panel.md.",
    )
    p.add_argument("take", help="a recording made with `puppet live --record`")
    p.add_argument("--curves", metavar="FILE", help="curves to start from (default: TAKE.curves if it exists)")
    p.add_argument("--port", type=int, default=None, metavar="PORT", help="port (default 8766 or the next free one)")
    p.add_argument("--lan", action="store_true", help="serve the LAN, behind a random token in the printed URL")
    p.add_argument("--rig", metavar="PATH", help="the rig the take was made with, if not the recorded path")
    p.add_argument("--device", action="append", default=[], metavar="SPEC",
                   help="a control box to re-record with (its default map, or --map); repeatable")
    p.add_argument("--map", metavar="FILE", help="mapping file for --device (default: each box's shipped map)")
    p.add_argument("--duration", type=float, metavar="S", help="stop serving after S seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import time

    from puppet.errors import PuppetError
    from puppet.live import StopFlag, check_duration
    from puppet.panel.editor import Editor
    from puppet.panel.server import DEFAULT_PORT, PanelServer, qr_text

    check_duration(args.duration)
    if args.port is not None and not 0 <= args.port <= 65535:
        raise PuppetError(f"--port {args.port} is outside 0..65535")
    editor = Editor(args.take, args.curves, args.rig)
    if args.device:
        from puppet.panel.boxes import BoxFeed

        editor.boxes = BoxFeed(args.device, editor.face.vocab, args.map)
        editor.boxes.start()
    for w in editor.session.warnings:
        print(f"puppet: warning: {w}", file=sys.stderr)
    srv = PanelServer("0.0.0.0" if args.lan else "127.0.0.1", DEFAULT_PORT + 1 if args.port is None else args.port,
                      "editor.html", editor.routes, try_ports=20 if args.port is None else 0)
    srv.start()
    print(f"puppet: force-graph editor for {editor.take.name} at {srv.url}", flush=True)
    if srv.lan:
        print(qr_text(srv.url), flush=True)
    stop = StopFlag()
    stop.install()
    t_end = None if args.duration is None else time.monotonic() + args.duration
    try:
        while not stop.stopped and (t_end is None or time.monotonic() < t_end):
            time.sleep(0.1)
    finally:
        stop.restore()
        srv.stop()
        if editor.boxes is not None:
            editor.boxes.close()
        editor.close()
    print(f"puppet: editor closed; curves are saved as {editor.curves_name} beside the take when you press save")
    return 0
