"""`puppet templates`: pictures of the recognition templates (each preset's displacement flow)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "templates",
        help="draw each preset's displacement flow field (the recognition templates) as PNG pictures",
        description="Settles the face, applies each expression preset and draws the skin's motion from "
        "the front: trails from blue (first frame) to red (settled), as seed 000's Fig. 8, or arrows "
        "coloured by length. Writes template_<preset>.png per preset and templates.png with all of them.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the pictures (created if missing)")
    p.add_argument("--rig", metavar="R", help="rig file (default: the built-in face)")
    p.add_argument("--face", metavar="SPEC", help="the face: ict (the scanned head), ict?identity=SEED, procedural or a saved identity's NAME")
    p.add_argument("--style", choices=("trails", "arrows"), default="trails")
    p.add_argument("--gain", type=float, default=1.0, metavar="X", help="magnify the motion (default 1, at most 100)")
    p.add_argument("--weight", type=float, default=1.0, metavar="W", help="preset weight 0..1 (default 1)")
    p.set_defaults(func=run)


#: The largest --gain: the presets move the skin by millimetres, magnified past this they leave the picture.
MAX_GAIN = 100.0


def run(args: argparse.Namespace) -> int:
    from puppet.capture.pictures import contact_sheet, draw_template, onset, save_png
    from puppet.errors import PuppetError
    from puppet.live import load_face
    from sim.facs import EXPRESSIONS, preset_face
    from sim.fit.basis import Settler, preset_values

    # --gain inf (or 1e308) drew a picture flooded by one arrow and said it was written
    if not 0 < args.weight <= 1 or not 0 < args.gain <= MAX_GAIN:
        raise PuppetError(f"--weight takes 0..1 and --gain a positive number up to {MAX_GAIN:g}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():  # was "cannot create the folder: File exists"
        raise PuppetError(f"{out}: a file is there; --out names the folder the pictures go into")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise PuppetError(f"{out}: cannot create the folder: {err.strerror}") from err
    face = load_face(args.rig, face=args.face)
    settler = Settler(face.model)
    images = []
    for name in EXPRESSIONS:
        frames = onset(face.model, settler.rest_state,
                       settler.values_for(preset_values(name, args.weight, preset_face(face.model.rig))))
        img = draw_template(face.model, frames, f"{name} (weight {args.weight:g})", args.style, gain=args.gain)
        save_png(img, out / f"template_{name}.png")
        images.append(img)
    save_png(contact_sheet(images), out / "templates.png")
    print(f"puppet: wrote {len(images)} template pictures and templates.png to {out}")
    return 0
