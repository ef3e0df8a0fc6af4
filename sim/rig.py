"""The rig file.

Rig file (`.npz`, version 1), read with `allow_pickle=False` so loading never executes code:
- `header`: a 0-d unicode array holding JSON: {"format": "facepuppet-rig", "version": 1, "name",
  "eye_radius", "landmarks": {name: vertex index}, "regions": [names], "muscles": [{"channel",
  "type": "linear"|"sphincter"|"sheet", "name", and the type's fields: points as [x, y, z] lists (cm),
  scalars as numbers}], "wrinkles": [WrinkleLine.to_dict() entries: name, points [[x, y], ...],
  muscles, widths, flags]}.
- arrays: `vertices` (N,3) f8, `triangles` (M,3) i4, `held` (N,) bool, `jaw_weight` (N,) f8,
  `jaw_pivot` (3,), `jaw_axis` (3,), `eye_centers` (2,3), `eye_loop_l`, `eye_loop_r`, `mouth_loop`
  (int), `uv` (N,2) optional, `region_<name>` (N,) bool per region.
Wrinkle lines (`sim.wrinkles.mask.WrinkleLine`) are stored as their plain `to_dict` form.
Fitted insertion gains (`FaceRig.insertion`, optional): header "insertion": [channel names], and an
array `insertion_<channel>` (N,) f8 >= 0 each.
Fitted skin material (`FaceRig.skin`, optional): header "skin": [names of "tether", "support",
"modulus"], and an array `skin_<name>` (N,) f8 >= 0 each (a multiplier of that material per vertex).
Named structures of the skin (`FaceRig.tissue`, optional): header "tissue": [names, each
"<skin field>_<structure>"], and an array `tissue_<name>` (N,) f8 >= 0 each (a multiplier of that
skin field per vertex, on top of `skin_<field>`).
Active strain (`FaceRig.strain`, optional; `sim.active_strain`): header "strain": [channel names],
and an array `strain_<channel>` (N,6) f8 in -1..1 each (xx, yy, zz, xy, xz, yz per vertex).
Tether anchors moved by a channel (`FaceRig.anchor`, optional; `sim.face.scan.anchor_fit`): header
"anchor": [channel names], and an array `anchor_<channel>` (N,3) f8 in -2..2 cm each.
Tether anchors carried by the turning eye (`FaceRig.gaze`, optional; `sim.face.scan.gaze_fit`):
header "gaze": [names "<in|out|up|down>_<l|r>"], and an array `gaze_<name>` (N,3) f8 in -2..2 cm each.
The integrator the face asks for (`FaceRig.integrator`, optional): header "integrator": "rk2" or
"implicit" (absent: "auto"; imported heads ask for "implicit").
Whose preset intensities the face takes (`FaceRig.presets`, optional): header "presets": a name of
`sim.facs.FACE_EXPRESSIONS` (absent: by the rig's name; imported heads: "imported-3", before it "imported-2", "imported").
"""

from __future__ import annotations

import json
import zipfile
import zlib
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

import numpy as np

from safefile import BadFile, atomic_write, load_json, not_a_file, number, quote, sequence, string, table
from sim.model import SKIN_FIELDS, FaceMesh, FaceRig, LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle

FORMAT = "facepuppet-rig"
VERSION = 1
_TYPES: dict[str, type] = {"linear": LinearMuscle, "sphincter": SphincterMuscle, "sheet": SheetMuscle,
                          "patch": PatchMuscle}
_TYPE_NAMES = {cls: name for name, cls in _TYPES.items()}
MAX_MEMBERS = 256
MAX_ARRAY_BYTES = 512 * 1024 * 1024
MAX_VERTICES = 2_000_000
INTEGRATORS = ("auto", "rk2", "implicit")  # FaceRig.integrator
#: FaceRig.gaze's names: each eye's four looks
GAZE_FIELDS = tuple(f"{look}_{side}" for side in ("l", "r") for look in ("in", "out", "up", "down"))
MAX_ENTRIES = 10_000  # muscles, landmarks, regions, wrinkle lines


class RigFileError(ValueError):
    """A rig file cannot be read: the message is one line naming the file and what is wrong."""


def _muscle_json(channel: str, m: Muscle) -> dict[str, Any]:
    out: dict[str, Any] = {"channel": channel, "type": _TYPE_NAMES[type(m)]}
    for f in fields(m):
        val = getattr(m, f.name)
        if f.default is not MISSING and val == f.default:  # a field added later: files without it unchanged
            continue
        out[f.name] = val if isinstance(val, str) else np.asarray(val, dtype=np.float64).tolist()
    return out


def save_rig(rig: FaceRig, path: str | Path) -> None:
    """Write the rig file described in the module docstring (beside the target, then renamed
    into place)."""
    with atomic_write(path, "wb") as fh:  # a failed save leaves the old rig as it was
        np.savez_compressed(fh, **rig_arrays(rig))


def rig_arrays(rig: FaceRig) -> dict[str, np.ndarray]:
    """The arrays of the rig file of `rig` (its "header" a 0-d JSON text), by name."""
    mesh = rig.mesh
    header = {
        "format": FORMAT,
        "version": VERSION,
        "name": rig.name,
        "eye_radius": float(mesh.eye_radius),
        "landmarks": {k: int(v) for k, v in mesh.landmarks.items()},
        "regions": sorted(mesh.regions),
        "muscles": [_muscle_json(ch, m) for ch, parts in rig.muscles.items() for m in parts],
        "wrinkles": [w.to_dict() for w in rig.wrinkles],
        "insertion": sorted(rig.insertion),
    }
    if rig.skin:  # rig files of faces with uniform skin are unchanged
        header["skin"] = sorted(rig.skin)
    if rig.tissue:  # likewise: rig files of faces without named structures are unchanged
        header["tissue"] = sorted(rig.tissue)
    if rig.strain:  # likewise: rig files of faces without active strain are unchanged
        header["strain"] = sorted(rig.strain)
    if rig.anchor:  # likewise: rig files of faces whose anchors stay are unchanged
        header["anchor"] = sorted(rig.anchor)
    if rig.gaze:  # likewise: rig files of faces without the tissue carried by the eyes are unchanged
        header["gaze"] = sorted(rig.gaze)
    if rig.integrator != "auto":  # rig files of faces that leave the choice to the simulator are unchanged
        header["integrator"] = rig.integrator
    if rig.presets:  # likewise: only a face that asks for other presets says so
        header["presets"] = rig.presets
    arrays: dict[str, np.ndarray] = {
        "header": np.array(json.dumps(header)),
        "vertices": np.asarray(mesh.vertices, np.float64),
        "triangles": np.asarray(mesh.triangles, np.int32),
        "held": np.asarray(mesh.held, bool),
        "jaw_weight": np.asarray(mesh.jaw_weight, np.float64),
        "jaw_pivot": np.asarray(mesh.jaw_pivot, np.float64),
        "jaw_axis": np.asarray(mesh.jaw_axis, np.float64),
        "eye_centers": np.asarray(mesh.eye_centers, np.float64),
        "eye_loop_l": np.asarray(mesh.eye_loops[0], np.int64),
        "eye_loop_r": np.asarray(mesh.eye_loops[1], np.int64),
        "mouth_loop": np.asarray(mesh.mouth_loop, np.int64),
    }
    if mesh.uv is not None:
        arrays["uv"] = np.asarray(mesh.uv, np.float64)
    for name, mask in mesh.regions.items():
        arrays[f"region_{name}"] = np.asarray(mask, bool)
    for name, gain in rig.insertion.items():
        arrays[f"insertion_{name}"] = np.asarray(gain, np.float64)
    for name, mult in rig.skin.items():
        arrays[f"skin_{name}"] = np.asarray(mult, np.float64)
    for name, mult in rig.tissue.items():
        arrays[f"tissue_{name}"] = np.asarray(mult, np.float64)
    for name, strain in rig.strain.items():
        arrays[f"strain_{name}"] = np.asarray(strain, np.float64)
    for name, anchor in rig.anchor.items():
        arrays[f"anchor_{name}"] = np.asarray(anchor, np.float64)
    for name, anchor in rig.gaze.items():
        arrays[f"gaze_{name}"] = np.asarray(anchor, np.float64)
    return arrays


def _array(data: Any, key: str, path: str, shape: tuple[int | None, ...], kind: str) -> np.ndarray:
    if key not in data.files:
        raise RigFileError(f"{path}: rig file lacks the array {key!r}")
    a = data[key]
    if a.dtype.kind not in kind:
        raise RigFileError(f"{path}: array {key!r} has dtype {a.dtype}, expected kind {kind!r}")
    if len(a.shape) != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        raise RigFileError(f"{path}: array {key!r} has shape {a.shape}, expected {shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise RigFileError(f"{path}: array {key!r} holds non-finite values")
    return a


def _bounded(data: Any, key: str, path: str, shape: tuple[int | None, ...], bounds: tuple[float, float],
             says: str) -> np.ndarray:
    """A float array of the rig file (`_array`) whose every value lies within bounds, as float64;
    else the error `says`."""
    a = _array(data, key, path, shape, "f")
    if np.any(a < bounds[0]) or np.any(a > bounds[1]):
        raise RigFileError(f"{path}: {says}")
    return a.astype(np.float64)


def _muscle(entry: Any, path: str) -> tuple[str, Muscle]:
    if not isinstance(entry, dict) or entry.get("type") not in _TYPES:
        raise RigFileError(f"{path}: muscle entry {quote(entry)} lacks a type in {sorted(_TYPES)}")
    cls = _TYPES[entry["type"]]
    kwargs: dict[str, Any] = {}
    for f in fields(cls):
        if f.name not in entry and f.default is not MISSING:  # written only where it is not the default
            continue
        if f.name not in entry:
            raise RigFileError(f"{path}: {entry['type']} muscle lacks the field {f.name!r}")
        val = entry[f.name]
        if f.name == "name":
            kwargs[f.name] = string(val, f"{path}: muscle name")
            continue
        try:
            arr = np.asarray(val, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise RigFileError(f"{path}: muscle field {f.name!r} is not numeric: {quote(val)}") from None
        if arr.shape not in ((), (3,)) or not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > 1e6):
            raise RigFileError(f"{path}: muscle field {f.name!r} must be a finite number or [x, y, z]")
        kwargs[f.name] = float(arr) if arr.shape == () else arr
    channel = entry.get("channel")
    if not isinstance(channel, str) or not 0 < len(channel) <= 200:
        raise RigFileError(f"{path}: muscle {quote(kwargs['name'])} lacks its channel name")
    return channel, cls(**kwargs)


def load_rig(path: str | Path) -> FaceRig:
    """Read a rig file; RigFileError (a ValueError) with a one-line message if it is malformed."""
    p = str(path)
    try:
        why = not_a_file(p, "rig file")
        if why:
            raise RigFileError(why)
        if not zipfile.is_zipfile(p):
            raise RigFileError(
                f"{p}: not a rig file (a rig is an .npz archive written by `puppet import-face`)"
            )
        _check_members(p)
        with np.load(p, allow_pickle=False) as data:
            return _parse(data, p)
    except RigFileError:
        raise
    except BadFile as err:
        raise RigFileError(str(err)) from err
    except FileNotFoundError:
        raise RigFileError(f"{p}: no such rig file") from None
    except (OSError, ValueError, zipfile.BadZipFile, KeyError, EOFError, zlib.error, RecursionError,
            NotImplementedError, OverflowError) as err:
        raise RigFileError(f"{p}: not a readable rig file ({type(err).__name__}: {quote(str(err), 80)})") from err


class _Arrays:
    """Arrays by name, read as an open npz is (`files`, `[name]`)."""

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self._arrays = arrays
        self.files = list(arrays)

    def __getitem__(self, key: str) -> np.ndarray:
        return self._arrays[key]


def rig_from_arrays(arrays: dict[str, np.ndarray], name: str) -> FaceRig:
    """The rig whose file's arrays (`rig_arrays`) are `arrays` (read elsewhere, e.g. mapped from
    the face cache), checked as `load_rig` checks a file's; RigFileError naming `name` if not."""
    try:
        return _parse(_Arrays(arrays), name)
    except RigFileError:
        raise
    except BadFile as err:
        raise RigFileError(str(err)) from err
    except (ValueError, KeyError, TypeError, RecursionError, OverflowError) as err:
        raise RigFileError(f"{name}: not a readable rig ({type(err).__name__}: {quote(str(err), 80)})") from err


def _check_members(p: str) -> None:
    """Every array's header is read and its promised size checked against the member's size and
    MAX_ARRAY_BYTES before numpy allocates anything (a forged header could ask for terabytes)."""
    from numpy.lib import format as npformat

    with zipfile.ZipFile(p) as z:
        infos = z.infolist()
        if len(infos) > MAX_MEMBERS:
            raise RigFileError(f"{p}: rig file holds {len(infos)} arrays; at most {MAX_MEMBERS}")
        for info in infos:
            with z.open(info) as fh:
                version = npformat.read_magic(fh)
                reader = npformat.read_array_header_1_0 if version == (1, 0) else npformat.read_array_header_2_0
                shape, _, dtype = reader(fh, max_header_size=10_000)
            size = int(np.prod(shape, dtype=object)) * max(1, dtype.itemsize)
            if dtype.hasobject or size > MAX_ARRAY_BYTES or size > info.file_size:
                raise RigFileError(f"{p}: array {quote(info.filename, 60)} promises {size} bytes of "
                                   f"{dtype} in a member of {info.file_size}; the rig file is damaged")


def load_model(path: str | Path) -> Any:
    """`load_rig` then `compile_model`; a rig that reads but does not compile (a file that is
    valid field by field but not as a face) is a RigFileError too, never a traceback."""
    from sim.build import compile_model

    rig = load_rig(path)
    try:
        return compile_model(rig)
    except Exception as err:  # noqa: BLE001 - the file's content, not a program error, reaches here
        raise RigFileError(f"{path}: the rig does not compile ({type(err).__name__}: "
                           f"{quote(str(err), 80)}); is it a rig written by `puppet import-face`?") from err


def _parse(data: Any, p: str) -> FaceRig:
    header_arr = _array(data, "header", p, (), "U")
    header = load_json(str(header_arr), p, "rig header")
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise RigFileError(f"{p}: not a {FORMAT} file")
    if header.get("version") != VERSION or isinstance(header.get("version"), bool):
        raise RigFileError(f"{p}: rig file version {quote(header.get('version'))}, this program reads {VERSION}")
    verts = _array(data, "vertices", p, (None, 3), "f")
    n = len(verts)
    if not 3 <= n <= MAX_VERTICES:
        raise RigFileError(f"{p}: rig has {n} vertices; expected 3 to {MAX_VERTICES}")
    tris = _array(data, "triangles", p, (None, 3), "iu")
    if tris.size and (tris.min() < 0 or tris.max() >= n):
        raise RigFileError(f"{p}: triangles refer to vertices outside 0..{n - 1}")
    loops = [_array(data, k, p, (None,), "iu") for k in ("eye_loop_l", "eye_loop_r", "mouth_loop")]
    for key, loop in zip(("eye_loop_l", "eye_loop_r", "mouth_loop"), loops):
        if loop.size and (loop.min() < 0 or loop.max() >= n):
            raise RigFileError(f"{p}: an eye or mouth loop refers to vertices outside 0..{n - 1}")
        if len(np.unique(loop)) < len(loop):
            # an opening whose border touched itself (an import before pinched borders were split):
            # the lid and lip rows walked it twice and the implicit integrator stopped with a traceback
            twice = int(np.flatnonzero(np.bincount(loop) > 1)[0])
            raise RigFileError(f"{p}: {key} passes vertex {twice} twice (the opening's border touches itself "
                               "there); import the head again with `puppet import-face`")
    landmarks = table(header.get("landmarks", {}), f"{p}: landmarks", MAX_ENTRIES)
    if not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < n for v in landmarks.values()):
        raise RigFileError(f"{p}: landmarks must map names to vertex indices in 0..{n - 1}")
    regions = {}
    for name in sequence(header.get("regions", []), f"{p}: regions", MAX_ENTRIES):
        name = string(name, f"{p}: region name")
        regions[name] = _array(data, f"region_{name}", p, (n,), "b")
    uv = _array(data, "uv", p, (n, 2), "f") if "uv" in data.files else None
    held = _array(data, "held", p, (n,), "b")
    if held.all():
        raise RigFileError(f"{p}: every vertex is held; a rig needs free skin to move")
    if np.abs(verts).max() > 1e6:
        raise RigFileError(f"{p}: vertex coordinates beyond 1e6 cm; the rig file is damaged")
    mesh = FaceMesh(
        vertices=verts.astype(np.float64),
        triangles=tris.astype(np.int32),
        landmarks={str(k): int(v) for k, v in landmarks.items()},
        held=held,
        jaw_weight=_array(data, "jaw_weight", p, (n,), "f"),
        jaw_pivot=_array(data, "jaw_pivot", p, (3,), "f"),
        jaw_axis=_array(data, "jaw_axis", p, (3,), "f"),
        eye_centers=_array(data, "eye_centers", p, (2, 3), "f"),
        eye_radius=number(header.get("eye_radius", 1.2), f"{p}: eye_radius", 0.0, 100.0, lo_open=True),
        eye_loops=(loops[0], loops[1]),
        mouth_loop=loops[2],
        regions=regions,
        uv=uv,
    )
    muscles: dict[str, tuple[Muscle, ...]] = {}
    entries = sequence(header.get("muscles", []), f"{p}: muscles", MAX_ENTRIES)
    for entry in entries:
        channel, m = _muscle(entry, p)
        muscles[channel] = muscles.get(channel, ()) + (m,)
    insertion = {}
    for name in sequence(header.get("insertion", []), f"{p}: insertion", MAX_ENTRIES):
        name = string(name, f"{p}: insertion channel")
        insertion[name] = _bounded(data, f"insertion_{name}", p, (n,), (0.0, 1e6),
                                   f"insertion gains of {quote(name)} must lie in 0..1e6")
    skin = {}
    for name in sequence(header.get("skin", []), f"{p}: skin", len(SKIN_FIELDS)):
        name = string(name, f"{p}: skin field")
        if name not in SKIN_FIELDS:
            raise RigFileError(f"{p}: skin field must be one of {', '.join(SKIN_FIELDS)}, not {quote(name[:40])}")
        skin[name] = _bounded(data, f"skin_{name}", p, (n,), (0.0, 1e3),
                              f"skin multipliers of {quote(name)} must lie in 0..1000")
    tissue = {}
    for name in sequence(header.get("tissue", []), f"{p}: tissue", MAX_ENTRIES):
        name = string(name, f"{p}: tissue structure")
        if name.split("_", 1)[0] not in SKIN_FIELDS or "_" not in name:
            raise RigFileError(f"{p}: a tissue structure is named <{'|'.join(SKIN_FIELDS)}>_<name>, "
                               f"not {quote(name[:40])}")
        tissue[name] = _bounded(data, f"tissue_{name}", p, (n,), (0.0, 1e3),
                                f"tissue multipliers of {quote(name)} must lie in 0..1000")
    strain = {}
    for name in sequence(header.get("strain", []), f"{p}: strain", MAX_ENTRIES):
        name = string(name, f"{p}: strain channel")
        strain[name] = _bounded(data, f"strain_{name}", p, (n, 6), (-1.0, 1.0),
                                f"active strain of {quote(name)} must lie in -1..1")
    anchor = {}
    for name in sequence(header.get("anchor", []), f"{p}: anchor", MAX_ENTRIES):
        name = string(name, f"{p}: anchor channel")
        anchor[name] = _bounded(data, f"anchor_{name}", p, (n, 3), (-2.0, 2.0),
                                f"anchor displacements of {quote(name)} must lie in -2..2 cm")
    gaze = {}
    for name in sequence(header.get("gaze", []), f"{p}: gaze", MAX_ENTRIES):
        name = string(name, f"{p}: gaze field")
        if name not in GAZE_FIELDS:
            raise RigFileError(f"{p}: a gaze field is one of {', '.join(GAZE_FIELDS)}, not {quote(name[:40])}")
        gaze[name] = _bounded(data, f"gaze_{name}", p, (n, 3), (-2.0, 2.0),
                              f"anchor displacements of the gaze's {quote(name)} must lie in -2..2 cm")
    integrator = header.get("integrator", "auto")
    if integrator not in INTEGRATORS:
        raise RigFileError(f"{p}: integrator must be one of {', '.join(INTEGRATORS)}, "
                           f"not {quote(str(integrator)[:40])}")
    presets = string(header["presets"], f"{p}: presets") if "presets" in header else ""
    return FaceRig(mesh=mesh, muscles=muscles, wrinkles=_wrinkles(header.get("wrinkles", []), p),
                   name=string(header.get("name", "rig"), f"{p}: name"), insertion=insertion,
                   skin=skin, integrator=integrator, presets=presets, tissue=tissue, strain=strain,
                   anchor=anchor, gaze=gaze)


def _wrinkles(entries: Any, p: str) -> tuple:
    if not entries:
        return ()
    from sim.wrinkles.mask import WrinkleLine

    out = []
    for entry in sequence(entries, f"{p}: wrinkles", MAX_ENTRIES):
        try:
            line = WrinkleLine.from_dict(entry)
            sizes = np.array([line.width_minus, line.width_plus, line.emphasis, line.furrow])
            if (len(line.points) > MAX_ENTRIES or not np.all(np.isfinite(line.points))
                    or np.abs(line.points).max() > 1e6 or not np.all(np.isfinite(sizes))
                    or np.abs(sizes).max() > 1e6):
                raise ValueError(f"wrinkle line {quote(line.name)} has points or sizes out of range")
            out.append(line)
        except (KeyError, ValueError, TypeError, AttributeError, OverflowError) as err:
            raise RigFileError(f"{p}: malformed wrinkle line ({type(err).__name__}: {quote(str(err), 80)})") from err
    return tuple(out)
