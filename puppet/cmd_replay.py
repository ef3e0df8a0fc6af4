"""`puppet replay`: play a recording (and/or keyframe curves) in the window, or export it."""

from __future__ import annotations

import argparse
import re
import sys
from typing import Any


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
    p.add_argument("--view", metavar="V",
                   help="window, video and images: shaded (default), wireframe, muscles, trails or heat")
    p.add_argument("--size", type=_size, metavar="WxH", help="video/image size (default 1280x720)")
    p.add_argument("--supersample", type=int, metavar="N",
                   help="video/images: N x N samples per pixel (smoother edges, N*N times the rendering; "
                   "default 1)")
    p.add_argument("--crf", type=int, metavar="Q",
                   help="video: H.264 quality, 0 (lossless) to 51 (worst); default 20")
    p.add_argument("--curves", metavar="FILE", help="keyframe curves, alone or layered over the recording")
    p.add_argument("--rig", metavar="PATH", help="the rig the recording was made with, if not the recorded path")
    p.add_argument("--face", metavar="SPEC", help="the face, if not the one recorded (ict, ict?identity=SEED, "
                   "procedural or a saved identity's NAME)")
    p.set_defaults(func=run)


#: the drawing options and the outputs they shape (None: the window, or the headless check)
DRAWING_OPTIONS = {"view": ("mp4", "frames", "png", None), "size": ("mp4", "frames", "png"),
                   "supersample": ("mp4", "frames", "png"), "crf": ("mp4",)}
KIND_WORDS = {"pc2": "a .pc2 point cache", "csv": "a .csv of channels", "arkit": "an .arkit.csv",
              "curves": "a .curves file", "obj": "an .obj mesh", "png": "a .png still",
              "frames": "PNG frames", "mp4": "an .mp4", None: "a replay without --out"}


def _or(given: Any, default: Any) -> Any:
    return default if given is None else given


def unused_options(args: argparse.Namespace, kind: str | None) -> str:
    """One line naming the drawing options given that do nothing for this output ('' if none):
    `--view wireframe --size 640x480` on a .csv export were dropped without a word."""
    if kind is None and (args.headless or args.file is None):
        kind_ok = ()  # a headless replay draws nothing
    else:
        kind_ok = (kind,)
    unused = [f"--{name}" for name, kinds in DRAWING_OPTIONS.items()
              if getattr(args, name) is not None and not set(kind_ok) & set(kinds)]
    from puppet.errors import not_applying

    return not_applying(unused, "a headless replay (it draws nothing)" if not kind_ok else KIND_WORDS[kind])


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
        note = unused_options(args, kind)  # said once the export is written: a failure stays one line
        fps = args.fps if args.fps is not None else (30.0 if kind in ("mp4", "frames", "png") else perf.rate)
        opts = ExportOptions(fps=fps, start=args.start, end=args.end, speed=args.speed, view=_or(args.view, "shaded"),
                             size=_or(args.size, (1280, 720)), supersample=_or(args.supersample, 1), crf=args.crf)
        if session is not None:
            from puppet.audio_take import take_audio

            opts.sound = take_audio(session)
        print(f"puppet: {export(perf, args.out, opts)}")
        if note:
            print(note, file=sys.stderr)
        return 0
    if not args.headless and live.display_available():
        from puppet.live import run_replay_window

        from puppet.audio_take import take_audio

        note = unused_options(args, None)
        if note:
            print(note, file=sys.stderr)
        sound = take_audio(session) if session is not None else None
        return run_replay_window(perf, start=args.start, end=args.end, speed=args.speed, view=_or(args.view, "shaded"),
                                 sound=sound)
    args.headless = True  # no display: the replay below draws nothing
    note = unused_options(args, None)
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
    if note:
        print(note, file=sys.stderr)
    return 0
