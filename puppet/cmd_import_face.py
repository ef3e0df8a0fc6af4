"""``puppet import-face MESH --landmarks FILE --out RIG``: give any head mesh the default face's
muscles, wrinkles, jaw, eyes and held border (seed 003 section 3; see docs/import-face.md).

Writes the rig (load it anywhere with ``--rig RIG``), a markdown report next to it
(``RIG.report.md``: scale, fit residuals, landmark distances, muscles) and a picture of the
transferred muscles on the new face (``RIG.png``)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from puppet.errors import ConfigError
from safefile import atomic_path, atomic_write


def register(subparsers: Any) -> None:
    """Add the ``import-face`` subcommand."""
    p = subparsers.add_parser(
        "import-face", help="make a rig for your own head mesh",
        description="Transfer the procedural face's rig (muscles, wrinkles, jaw, eyes, held border; "
                    "not the scanned head's) onto a head mesh (OBJ, PLY, glTF/GLB; any scale and orientation) marked with landmarks.")
    p.add_argument("mesh", metavar="MESH", help="head or face mesh: .obj, .ply, .gltf, .glb, .off, .stl")
    p.add_argument("--landmarks", required=True, metavar="FILE",
                   help="JSON: landmark name -> vertex index or [x, y, z] (docs/import-face.md)")
    p.add_argument("--out", required=True, metavar="RIG", help="rig file to write (.npz)")
    p.add_argument("--rig", metavar="RIG", default=None,
                   help="rig to transfer from (default: the procedural face at --resolution)")
    p.add_argument("--resolution", type=int, choices=(0, 1, 2), default=1,
                   help="resolution of the procedural reference face (default 1)")
    p.add_argument("--name", default=None, help="rig name (default: the mesh file's stem)")
    p.add_argument("--no-image", action="store_true", help="do not render the muscles picture")
    p.add_argument("--rest-eyes", action="store_true",
                   help="open each eye to a resting eye's height (the upper lid over the iris' top) and "
                        "seat the eyeball behind the lids, from the head's own geometry (docs/import-face.md)")
    p.add_argument("--rest-lips", action="store_true",
                   help="bring lips that stand apart at rest together, to the reference face's gap "
                        "(docs/import-face.md)")
    p.set_defaults(func=run)


def _reference(args: argparse.Namespace) -> Any:
    from sim.face import default_rig
    from sim.rig import RigFileError, load_rig

    if args.rig is None:
        return default_rig(args.resolution)
    try:
        return load_rig(args.rig)
    except RigFileError as err:
        raise ConfigError(str(err)) from err


def _render(model: Any, path: Path) -> str | None:
    """Render the muscles view; a missing OpenGL stack is a warning, not a failed import."""
    try:
        from render.offscreen import render_to_file

        with atomic_path(path) as tmp:
            render_to_file(model, model.rest_state(), tmp, size=(960, 960), view="muscles")
    except Exception as err:  # EGL/Mesa missing or broken: the rig itself is still good
        print(f"puppet: warning: could not render {path} ({type(err).__name__}: {err})".splitlines()[0],
              file=sys.stderr)
        return None
    return str(path)


def _drawn_here(picture: Path, report: Path) -> bool:
    """Whether RIG.png may be (re)drawn: it is not there, or the report of an earlier import beside
    it shows it (a texture of the head's own name never is)."""
    if not picture.exists():
        return True
    try:
        with open(report, encoding="utf-8", errors="replace") as fh:
            return f"]({picture.name})" in fh.read(1 << 20)
    except OSError:
        return False


def run(args: argparse.Namespace) -> int:
    """Read, transfer, compile (proves the rig simulates), save, report, render."""
    from sim.build import compile_model
    from sim.rig import save_rig
    from sim.face.transfer import TransferError, read_landmarks, read_mesh, transfer_rig
    from sim.face.transfer.pipeline import TransferOptions
    from sim.face.transfer.report import format_report

    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise ConfigError(f"{out}: rig files end in .npz")
    if not out.parent.is_dir():
        raise ConfigError(f"{out}: the folder {out.parent} does not exist")
    start = time.perf_counter()
    try:
        head = read_mesh(args.mesh)
        landmarks = read_landmarks(args.landmarks)
        result = transfer_rig(_reference(args), head, landmarks, name=args.name or Path(args.mesh).stem,
                              options=TransferOptions(seat_eyes=args.rest_eyes, rest_lips=args.rest_lips,
                                                      cover_sheets=True, match_forces=True, refine=True,
                                                      place_lower_lids=True))
    except TransferError as err:
        raise ConfigError(str(err)) from err
    try:
        model = compile_model(result.rig)
    except ValueError as err:  # a reference rig the builder rejects once moved onto this mesh
        raise ConfigError(f"{args.mesh}: the transferred rig does not compile ({err})".splitlines()[0]) from err
    try:
        save_rig(result.rig, out)  # beside the target, then renamed: an old rig survives a failure
    except OSError as err:
        raise ConfigError(f"{out}: cannot write the rig: {err.strerror or err}") from err
    seconds = time.perf_counter() - start
    report = out.with_suffix(".report.md")
    picture = out.with_suffix(".png")
    image = None
    if args.no_image:
        pass
    elif _drawn_here(picture, report):
        image = _render(model, picture)
    else:
        print(f"puppet: warning: {picture} is not a picture import-face drew (a texture?): kept; the muscles "
              "picture is not drawn (give --out another name to get it)", file=sys.stderr)
    with atomic_write(report) as fh:
        fh.write(format_report(result, args.mesh, args.landmarks, seconds, Path(image).name if image else None))
    m = result.rig.mesh
    print(f"wrote {out} ({len(m.vertices)} vertices, {sum(len(p) for p in result.rig.muscles.values())} "
          f"muscle parts, scale x{result.similarity.scale:.4g} to cm) in {seconds:.1f} s")
    print(f"report: {report}" + (f"; picture: {image}" if image else ""))
    if result.dense:
        print(f"puppet: warning: {args.mesh}: {result.dense}", file=sys.stderr)
    return 0
