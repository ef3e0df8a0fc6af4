"""``puppet pose``: simulate the face from rest under fixed channel values and write the result.

Outside checks rely on this contract:
    puppet pose [--rig PATH] [--face SPEC] [--resolution N] [--set CHANNEL=VALUE]... [--au AU12=0.8]...
                [--expression NAME[=WEIGHT]]... [--age YEARS] [--seconds S] --out FILE
                [--size WxH] [--view VIEW]
FILE .npz: arrays rest (N,3), positions (N,3), surface (N,3), triangles (M,3), landmark_names (K,),
landmark_indices (K,), and for the scanned head scan_rest and scan_positions (26719,3), the whole scan in
its own vertex order, posed as drawn (the lids laid back onto the eyeballs where the simulated
margins sink into the cornea: sim.face.scan.lid_contact; `surface` is the simulation's own); .obj:
the drawn surface (the scanned head: the whole posed scan as scan_positions, its 26719 vertices and
its faces in the scan's order); .png/.jpg/.jpeg: rendered by render.offscreen.
Values combine in this order: expressions, then AUs (each raises its channels to max(current,
weight * intensity)), then --set (overrides), then --age.
"""

from __future__ import annotations

import argparse
import sys
from collections import deque
from pathlib import Path
from typing import Any

from puppet.errors import ChannelError, ConfigError, PuppetError, not_applying

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
HISTORY_SECONDS = 2.0


def register(subparsers: Any) -> None:
    """Add the ``pose`` subcommand."""
    p = subparsers.add_parser(
        "pose",
        help="simulate a still pose and write it (.npz, .obj or an image)",
        description="Simulate the face from rest under fixed channel values, AUs or expressions.",
    )
    p.add_argument("--rig", metavar="PATH", help="rig file (default: the built-in face, see --face)")
    p.add_argument("--face", metavar="SPEC", default=None,
                   help="the face: ict (the scanned head), ict?identity=SEED, procedural or a saved identity's NAME")
    p.add_argument("--resolution", type=int, default=None, metavar="N",
                   help="procedural face resolution: 0 ~ 860, 1 ~ 2.7k, 2 ~ 12k vertices (default 0; alone, it "
                   "picks the procedural face)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="CHANNEL=VALUE",
                   help="set one channel (repeatable); see `puppet channels`")
    p.add_argument("--au", dest="aus", action="append", default=[], metavar="AU=INTENSITY",
                   help="apply a FACS action unit 0..1, e.g. AU12=0.8 or AU12_R=0.8 (repeatable)")
    p.add_argument("--expression", dest="expressions", action="append", default=[],
                   metavar="NAME[=WEIGHT]", help="apply an expression preset, weight 0..1 (repeatable)")
    p.add_argument("--age", type=float, default=None, metavar="YEARS", help="age in years (default 30)")
    p.add_argument("--seconds", type=float, default=None, metavar="S",
                   help="simulated seconds (default: until the face has settled, at most 5 s)")
    p.add_argument("--out", required=True, metavar="FILE", help="output .npz, .obj, .png or .jpg")
    p.add_argument("--size", metavar="WxH", help="image size (default 1280x720)")
    p.add_argument("--view", metavar="VIEW", help="image: shaded, wireframe, muscles, trails or heat (default shaded)")
    p.set_defaults(func=run)


def _pair(text: str, what: str) -> tuple[str, str | None]:
    name, sep, value = text.partition("=")
    if not name.strip():
        raise ChannelError(f"{what} {text!r}: expected NAME=VALUE")
    return name.strip(), (value.strip() if sep else None)


def _number(text: str | None, what: str) -> float:
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ChannelError(f"{what}: expected a number, got {text!r}") from None


def _size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        raise PuppetError(f"--size {text!r}: expected WxH, e.g. 1280x720") from None
    if not sep or min(size) < 1:
        raise PuppetError(f"--size {text!r}: expected WxH, e.g. 1280x720")
    from render.offscreen import MAX_IMAGE_SIDE

    if max(size) > MAX_IMAGE_SIDE:
        raise PuppetError(f"--size {text!r}: at most {MAX_IMAGE_SIDE} pixels a side")
    return size


def build_control(args: argparse.Namespace, face: str | None = None) -> Any:
    """The FaceControl the options ask for (presets at the intensities of `face`, its rig's name);
    puppet ChannelError (exit 2) for bad names or values."""
    from sim import channels as ch
    from sim import facs
    from sim.state import FaceControl

    control = FaceControl()
    try:
        for text in args.expressions:
            name, value = _pair(text, "--expression")
            facs.apply_expression(control, name, 1.0 if value is None else _number(value, f"--expression {name}"),
                                  face)
        for text in args.aus:
            name, value = _pair(text, "--au")
            if value is None:
                raise ChannelError(f"--au {text!r}: expected AU=INTENSITY, e.g. AU12=0.8")
            facs.apply_au(control, name, _number(value, f"--au {name}"))
        for text in args.sets:
            name, value = _pair(text, "--set")
            if value is None:
                raise ChannelError(f"--set {text!r}: expected CHANNEL=VALUE, e.g. jaw=0.5")
            control.set(name, _number(value, f"--set {name}"))
        if args.age is not None:
            control.set("age", args.age)
    except ch.ChannelError as err:
        raise ChannelError(str(err)) from err
    return control


def load_model(args: argparse.Namespace) -> Any:
    """The FaceModel: the rig file if given, else the default face at --resolution."""
    if args.rig:
        from sim.rig import RigFileError
        from sim.rig import load_model as load_rig_model

        if args.resolution is not None:  # it was ignored without a word
            raise ConfigError(f"--resolution {args.resolution}: a rig file has its own mesh; leave out --resolution")

        try:
            return load_rig_model(args.rig)
        except RigFileError as err:
            raise ConfigError(str(err)) from err
    from puppet.faces import parse_face

    spec = args.face if args.face is not None else ("procedural" if args.resolution is not None else None)
    choice = parse_face(spec, 0 if args.resolution is None else args.resolution)
    if choice.kind != "procedural" and args.resolution is not None:  # ignored without a word before
        raise ConfigError(f"--resolution {args.resolution}: the resolutions are the procedural face's; --face "
                          f"{choice.spec} has one mesh (leave out --resolution, or use --face procedural)")
    if choice.kind == "ict":
        from puppet.face_cache import scan_model

        return scan_model(choice.weights if choice.weights.any() else None)
    from sim.face import default_model

    return default_model(choice.resolution)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the pose."""
    out = Path(args.out)
    suffix = out.suffix.lower()
    if suffix not in (".npz", ".obj", *IMAGE_SUFFIXES):
        raise PuppetError(f"--out {args.out}: unknown file type; use .npz, .obj, .png, .jpg or .jpeg")
    if not out.parent.is_dir():  # said before the simulation (it was said after it, 10-30 s later)
        why = "is not a folder" if out.parent.exists() else "does not exist"
        raise PuppetError(f"{out}: the folder {out.parent} {why}")
    if out.is_dir():
        raise PuppetError(f"--out {out}: is a folder; name the file to write in it")
    unused = [f"--{name}" for name in ("size", "view") if getattr(args, name) is not None]
    # dropped without a word before; said once the pose is written (a failure stays one line)
    note = not_applying(unused if suffix not in IMAGE_SUFFIXES else [], f"{suffix} (only images are drawn)")
    args.size = "1280x720" if args.size is None else args.size
    args.view = "shaded" if args.view is None else args.view
    size = _size(args.size)
    if suffix in IMAGE_SUFFIXES:  # an unknown view was a ValueError traceback after the simulation
        from render.renderer import VIEWS

        if args.view not in VIEWS:
            raise PuppetError(f"--view {args.view!r}: choose one of {', '.join(VIEWS)}")
    if args.seconds is not None and not (0.0 <= args.seconds <= 600.0):
        raise PuppetError(f"--seconds {args.seconds:g}: expected 0..600")
    build_control(args)  # bad names and values fail before the face is built
    model = load_model(args)
    from sim.facs import preset_face

    control = build_control(args, preset_face(model.rig))

    from sim.integrator import Simulator

    sim = Simulator(model)
    state = model.rest_state()
    history: deque = deque(maxlen=max(1, int(HISTORY_SECONDS / sim.frame_dt)))
    if args.seconds is not None:
        for _ in range(int(round(args.seconds / sim.frame_dt))):
            sim.step(state, control)
            history.append(state.surface.copy())
        seconds = float(args.seconds)
    else:
        seconds = 0.0
        while True:  # Simulator.settle's rule, frame by frame so the history holds the motion
            sim.step(state, control)
            seconds += sim.frame_dt
            history.append(state.surface.copy())
            if seconds >= 5.0 - 1e-9 or (seconds >= 0.1 and _settled(state)):
                break
    for ev in sim.guard_events:
        print(f"puppet: warning: simulation guard at t={ev.time:.3f} s: {ev.reason} (state restored)",
              file=sys.stderr)
    if history:
        history.pop()  # the newest surface is the state itself
    write_pose(model, state, out, size=size, view=args.view, history=list(history))
    from puppet.export.scan import scan_dressing

    dressing = scan_dressing(model) if suffix in (".npz", ".obj") else None
    what = f"{len(model.rest)} vertices" if dressing is None else \
        f"{len(model.rest)} simulated skin vertices posing the scan's {len(dressing.rest)}"
    print(f"pose: {what}, {seconds:.2f} s simulated, wrote {out}")
    if note:
        print(note, file=sys.stderr)
    return 0


def _settled(state: Any) -> bool:
    import numpy as np

    from sim.integrator import SETTLE_SPEED

    return float(np.sqrt(np.max(np.sum(state.velocities**2, axis=1)))) < SETTLE_SPEED


def write_pose(model: Any, state: Any, out: Path, *, size: tuple[int, int] = (1280, 720),
               view: str = "shaded", history: list | None = None) -> None:
    """Write the state as .npz, .obj or an image (see the module docstring), beside `out` and
    renamed into place, so a failure leaves an old file as it was."""
    import numpy as np

    from safefile import atomic_path, atomic_write

    from puppet.export.scan import posed, scan_dressing, write_scan_obj

    suffix = out.suffix.lower()
    dressing = scan_dressing(model) if suffix in (".npz", ".obj") else None
    if suffix == ".obj" and dressing is not None:  # the scanned head: the scan's vertices and faces
        with atomic_path(out) as tmp:
            write_scan_obj(tmp, posed(dressing, state), f"puppet pose, model {model.hash}, t = {state.time:.4f} s, "
                           "cm; the scanned head's 26719 vertices in the scan's order (ICT FaceKit topology)")
        return
    extra = {} if dressing is None else {"scan_rest": np.asarray(dressing.rest, np.float64),
                                         "scan_positions": np.asarray(posed(dressing, state), np.float64)}
    if suffix == ".npz":
        names = sorted(model.mesh.landmarks)
        with atomic_write(out, "wb") as fh:
            np.savez(
                fh,
                **extra,
                rest=np.asarray(model.rest, np.float64),
                positions=np.asarray(state.positions, np.float64),
                surface=np.asarray(state.surface, np.float64),
                triangles=np.asarray(model.triangles, np.int32),
                landmark_names=np.array(names, dtype=np.str_),
                landmark_indices=np.array([model.mesh.landmarks[n] for n in names], dtype=np.int64),
            )
    elif suffix == ".obj":
        from sim.face.turn import state_turn, turn_head, turn_weights

        # as drawn and as a PC2 holds it: the head turned on the neck (head_yaw/pitch/roll); the
        # skin is simulated in the head's frame, and the OBJ was written unturned
        surface = turn_head(state.surface, turn_weights(model.rest), *state_turn(state))
        with atomic_write(out, "w", encoding="ascii") as fh:
            fh.write(f"# puppet pose, model {model.hash}, t = {state.time:.4f} s, cm\n")
            for x, y, z in surface:
                fh.write(f"v {x:.6f} {y:.6f} {z:.6f}\n")
            for a, b, c in np.asarray(model.triangles) + 1:
                fh.write(f"f {a} {b} {c}\n")
    else:
        try:
            from render.offscreen import render_to_file
        except ImportError as err:
            raise PuppetError(f"cannot write {out}: the offscreen renderer is not available ({err})") from err
        with atomic_path(out) as tmp:
            render_to_file(model, state, tmp, size=size, view=view, history=history)
