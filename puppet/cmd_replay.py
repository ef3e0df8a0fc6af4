"""`puppet replay`: play a recording (and/or keyframe curves) in the window, or export it."""

from __future__ import annotations

import argparse
import re
import sys


def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)x(\d+)", text.strip().lower())
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT like 1280x720, got {text!r}")
    from render.offscreen import MAX_IMAGE_SIDE

    if max(int(m.group(1)), int(m.group(2))) > MAX_IMAGE_SIDE:
        raise argparse.ArgumentTypeError(f"at most {MAX_IMAGE_SIDE} pixels a side, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "replay",
        help="replay a recorded session (window with transport keys, or export with --out)",
        description="Re-simulate a recording exactly. --out picks the export by suffix: .mp4, a folder "
        "(PNG frames), .png, .obj (the posed mesh at --from), .pc2 (+ .obj), .csv (channels), .arkit.csv (ARKit blendshapes), .curves "
        "(editable keyframe curves). Window keys: SPACE pause, LEFT/RIGHT seek 1 s, UP/DOWN speed, "
        "HOME restart, N next marker, ESC quit. See docs/live.md.",
    )
    p.add_argument("file", nargs="?", help="a recording made with `puppet live --record`")
    p.add_argument("--headless", action="store_true", help="no window")
    p.add_argument("--out", metavar="PATH", help="export instead of playing")
    p.add_argument("--fps", type=float, metavar="N",
                   help="export frame rate (default 30 for video and images, the tick rate for data)")
    p.add_argument("--from", dest="start", type=float, default=0.0, metavar="T", help="start at T seconds")
    p.add_argument("--to", dest="end", type=float, metavar="T", help="end at T seconds")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="playback speed (2 = twice as fast)")
    p.add_argument("--view", default="shaded", metavar="V",
                   help="shaded, wireframe, muscles, trails or heat")
    p.add_argument("--size", type=_size, default=(1280, 720), metavar="WxH", help="video/image size")
    p.add_argument("--supersample", type=int, default=1, metavar="N",
                   help="video/images: N x N samples per pixel (smoother edges, N*N times the rendering; "
                   "default 1)")
    p.add_argument("--crf", type=int, metavar="Q",
                   help="video: H.264 quality, 0 (lossless) to 51 (worst); default 20")
    p.add_argument("--curves", metavar="FILE", help="keyframe curves, alone or layered over the recording")
    p.add_argument("--rig", metavar="PATH", help="the rig the recording was made with, if not the recorded path")
    p.add_argument("--face", metavar="SPEC", help="the face, if not the one recorded (ict, ict?identity=SEED, "
                   "procedural or a saved identity's NAME)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from puppet import live
    from puppet.curves import load_curves
    from puppet.errors import PuppetError
    from puppet.replay import Replayer, build_performance, state_digest
    from puppet.session import read_session

    if args.file is None and args.curves is None:
        raise PuppetError("give a recording FILE and/or --curves FILE")
    if args.out:
        from pathlib import Path

        for given in (args.file, args.curves):
            if given and Path(args.out).resolve() == Path(given).resolve():
                raise PuppetError(f"--out {args.out}: that is the file being replayed ({given}); name another file")
    session = read_session(args.file) if args.file else None
    if session is not None:
        for w in session.warnings:
            print(f"puppet: warning: {w}", file=sys.stderr)
    curves = load_curves(args.curves) if args.curves else None
    perf = build_performance(session, curves, args.rig, face=args.face)
    if perf.ticks == 0 and session is not None:
        empty = (f"{session.path} holds no performance (its header only: the show stopped before its "
                 "first tick)")
        if args.out:
            raise PuppetError(f"{empty}; nothing to export, {args.out} is left as it was")
        print(f"puppet: {empty}; replayed an empty take")
        return 0
    if args.out:
        from puppet.export.runner import ExportOptions, export, kind_of

        kind = kind_of(__import__("pathlib").Path(args.out))
        fps = args.fps if args.fps is not None else (30.0 if kind in ("mp4", "frames", "png") else perf.rate)
        opts = ExportOptions(fps=fps, start=args.start, end=args.end, speed=args.speed, view=args.view,
                             size=args.size, supersample=args.supersample, crf=args.crf)
        if session is not None:
            from puppet.audio_take import take_audio

            opts.sound = take_audio(session)
        print(f"puppet: {export(perf, args.out, opts)}")
        return 0
    if not args.headless and live.display_available():
        from puppet.live import run_replay_window

        from puppet.audio_take import take_audio

        sound = take_audio(session) if session is not None else None
        return run_replay_window(perf, start=args.start, end=args.end, speed=args.speed, view=args.view, sound=sound)
    rp = Replayer(perf)
    end_tick = perf.ticks if args.end is None else min(perf.ticks, int(round(args.end * perf.rate)))
    rp.seek(end_tick)
    checked = ""
    if perf.checks:
        if rp.mismatches:
            raise PuppetError(f"replay diverged from the recording at tick {rp.mismatches[0]} "
                              f"(different rig, program or numpy build?)")
        checked = f"; bit-identical to the live session at {rp.verified} checkpoints"
    print(f"puppet: replayed {rp.tick} ticks ({rp.tick / perf.rate:.2f} s){checked}; "
          f"final state {state_digest(rp.state)}")
    return 0
