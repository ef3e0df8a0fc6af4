"""``puppet view``: open a window on a posed face (the pose command's options), to orbit, zoom and
switch views. Without a display it says so in one line and writes an offscreen image instead.

    puppet view [pose options: --rig, --resolution, --set, --au, --expression, --age, --seconds]
                [--size WxH] [--view VIEW] [--out FALLBACK.png] [--antialias auto|none|fxaa]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from puppet.errors import PuppetError

DEFAULT_FALLBACK = "puppet-view.png"
SETTLE_LIMIT_S = 5.0


def _pose_parser() -> argparse.ArgumentParser:
    """The pose command's parser, so `view` takes exactly the same posing options."""
    from puppet import cmd_pose

    sub = argparse.ArgumentParser(add_help=False).add_subparsers()
    cmd_pose.register(sub)
    return sub.choices["pose"]


def register(subparsers: Any) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view", parents=[_pose_parser()], conflict_handler="resolve",
        help="open a window on a posed face (orbit, zoom, views; ? for keys)",
        description="Pose the face like `puppet pose` and show it in a window. Keys: drag to orbit, "
                    "scroll to zoom, R/Home reset, 1-5 or V views, F11 fullscreen, ? help, Esc quit.",
    )
    p.add_argument("--out", default=None, metavar="FILE",
                   help=f"image written instead when there is no display (default {DEFAULT_FALLBACK}, "
                        "or the next free puppet-view.N.png beside it: an earlier picture is never replaced "
                        "unless named)")
    p.add_argument("--size", default="1280x720", metavar="WxH", help="window size (default 1280x720)")
    p.add_argument("--view", default="shaded", metavar="VIEW",
                   help="shaded, wireframe, muscles, trails or heat (default shaded)")
    p.add_argument("--antialias", default="auto", choices=("auto", "none", "fxaa"),
                   help="auto: FXAA on a GPU, none on software OpenGL (default auto)")
    p.set_defaults(func=run)


def pose(model: Any, control: Any, seconds: float | None) -> tuple[Any, list[Any]]:
    """Simulate from rest under `control` for `seconds` (None: until settled, at most 5 s);
    returns the state and the surfaces of the last two seconds, oldest first, for the trails."""
    from sim.integrator import Simulator

    from puppet import cmd_pose

    sim = Simulator(model)
    state = model.rest_state()
    keep = max(1, int(cmd_pose.HISTORY_SECONDS / sim.frame_dt))
    history: list[Any] = []
    t = 0.0
    limit = SETTLE_LIMIT_S if seconds is None else seconds
    while t < limit - 1e-9:
        sim.step(state, control)
        t += sim.frame_dt
        history = (history + [state.surface.copy()])[-keep:]
        if seconds is None and t >= 0.1 and cmd_pose._settled(state):
            break
    return state, history[:-1]


def free_name(path: Path, limit: int = 9999) -> Path:
    """`path` when nothing is there, else the first free `STEM.N.SUFFIX` beside it (N = 1..limit);
    a PuppetError when every one is taken."""
    if not os.path.lexists(path):
        return path
    for n in range(1, limit + 1):
        candidate = path.with_name(f"{path.stem}.{n}{path.suffix}")
        if not os.path.lexists(candidate):
            return candidate
    raise PuppetError(f"{path}: it and {path.stem}.1..{limit}{path.suffix} are all taken; "
                      "pass --out FILE or move the pictures away")


def run(args: argparse.Namespace) -> int:
    from puppet import cmd_pose
    from render.renderer import VIEWS

    if args.view not in VIEWS:
        raise PuppetError(f"--view {args.view!r}: choose one of {', '.join(VIEWS)}")
    out = Path(args.out) if args.out is not None else Path(DEFAULT_FALLBACK)
    if out.suffix.lower() not in cmd_pose.IMAGE_SUFFIXES:
        raise PuppetError(f"--out {args.out}: the fallback image must be .png, .jpg or .jpeg")
    size = cmd_pose._size(args.size)
    if args.seconds is not None and not (0.0 <= args.seconds <= 600.0):
        raise PuppetError(f"--seconds {args.seconds:g}: expected 0..600")
    cmd_pose.build_control(args)  # bad names and values fail before the face is built
    model = cmd_pose.load_model(args)
    from sim.facs import preset_face

    # the presets at the face's own intensities, as `puppet pose` plays them (the scanned head's
    # surprise was drawn without its raised lids, AU5, and with the jaw at 0.4 instead of 0.5)
    control = cmd_pose.build_control(args, preset_face(model.rig))
    state, history = pose(model, control, args.seconds)

    from render.hud import HudInfo, active_channels
    from render.window import FaceWindow, NoDisplayError

    hud = HudInfo(channels=active_channels(model.channels, control.values), age=state.age)
    try:
        window = FaceWindow(model, size=size, view=args.view,
                            antialias=None if args.antialias == "auto" else args.antialias)
    except NoDisplayError as err:
        from render.offscreen import render_to_file
        from safefile import atomic_path

        if args.out is None:  # the default name: an earlier view's picture is kept, not replaced
            out = free_name(out)
        with atomic_path(out) as tmp:  # renamed into place when complete
            render_to_file(model, state, tmp, size=size, view=args.view, history=history, hud=hud)
        print(f"puppet view: {err}; wrote {out.resolve()} instead", file=sys.stderr)
        return 0
    with window:
        window.state = state
        window.hud = HudInfo(**{**hud.__dict__, "lines": ["? for keys"]})
        if history and window.renderer.trails is not None:
            window.renderer.trails.set(history)
        window.run(wait=0.25)  # a still pose: redraw on input, not continuously
    return 0
