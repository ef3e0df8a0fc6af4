"""Does a third-party head carrying the transferred rig read as the presets? The observer of
`benchmarks/observer.py` (fer's FER2013 classifier) on heads that are not ours (run by hand).

The heads are not shipped and never used by the tests; this benchmark reads them from a folder
(`--meshes DIR`, default `$PUPPET_MESHES` or `~/.cache/facepuppet/meshes`) and, when a file is
missing, downloads it by hand from its public address (the product itself never downloads). Where the machine
cannot reach those addresses, copy each file from a local clone of its repository into the folder
under the name below (`git -C CLONE show COMMIT:PATH > DIR/NAME`):

- `makehuman` (development head): the MakeHuman base mesh `hm08`, `makehuman/data/3dobjs/base.obj`
  of https://github.com/makehumancommunity/makehuman (commit a8bc2d54; released CC0 1.0 by Data
  Collection AB, Joel Palmius and Jonas Hauquier, 2020). A modelled full body: the skin group
  ("body") above the shoulders is kept. Its eyes are open (the lids roll into the socket) and its
  lips are apart at the front, the mouth's lining closing behind them: the eye and lip rims are
  declared as closed loops (the lining and the sockets inside them are removed).
- `makehuman-mask` (development head): the same MakeHuman head cut to a face mask (the skin in
  front of the jaw angles, from under the chin to the hairline), the development stand-in for a
  face tracker's canonical mesh, which has no head round the face.
- `makehuman-lowres` (development head): the MakeHuman face mask decimated by quadric error
  (`fast_simplification`, in the `observe` extra) to about 470 vertices, the resolution of a face
  tracker's canonical mesh, so the transfer is tried on that kind of input without the held-out
  one: a coarse mask, no head round it, no eyeballs, no mouth inside once its rims are opened.
- `leeperrysmith` (held out: measured once, nothing tuned on it): "Infinite, 3D Head Scan by Lee
  Perry-Smith" (Infinite-Realities, based on a work at www.triplegangers.com), CC BY 3.0 Unported,
  as distributed with the three.js examples: `examples/obj/leeperrysmith/LeePerrySmith.js` of
  https://github.com/mrdoob/three.js (commit 3232c8201a59dc1515500a139bd0e7b75a9e2a42; three.js
  JSON model format 2, 8,838 vertices). A scan with closed lids and closed lips: the lid and lip
  lines are declared as slits.
- `nefertiti` (development head): the bust of Nefertiti (Egyptian Museum, Berlin), scanned by Nora
  Al-Badri and Jan Nikolai Nelles in 2016 and released into the public domain; the remeshed
  35,002-vertex version `objects/nefertiti/nefertiti-lowres.obj` of
  https://github.com/odedstein/meshes (commit 835213277571d625722d25880c9c3010c6f45a5a; the remesh
  also released into the public domain), in mm. A sculpture: the eyeballs are carved in one
  surface with open lids (the eye rims are declared as closed loops, the carved eyeball inside
  them removed), the lips are closed (the lip line is declared as a slit). Crown, neck and
  shoulders are kept (held as the back of a head is).

- `ict-identity` (development): the scanned head shipped with the product (the ICT FaceKit, MIT)
  with the identity of seed 7 (`--face ict?identity=7`), exported as a third party would find it:
  the skin alone (face and head-neck parts; no eyeballs, teeth or mouth socket), its eyes and lips
  holes the importer finds, its landmarks the scan's own vertices (`sim/face/scan/landmarks.json`).
  A scan of a real person, not a modelled head; nothing is downloaded.
- `ict-shut` (development): the same skin with the scan's own blinks (eyeBlink_L and _R at 1) and
  each eye's hole closed by a strip of triangles joining its rims from corner to corner, so its
  lids are one shut surface as a scan with closed eyes is; the lid lines are declared as slits.

- `ict-shut-corner` (development): `ict-shut` with each lid line traced one edge further at the
  inner corner (to the corner's neighbour furthest towards the nose and up), the corner landmarks
  left where they are: a line snapped to a scan's vertices can start so. It showed the held-out
  scan's fault (one eye a blank, crumpled lid) until the transfer's lids no longer turned on it.

- `ict-shut-squeezed` (development): `ict-shut` with the eyes squeezed shut (the scan's own
  cheekSquint_L and _R at 1 over the blinks): the raised cheeks push the lower lids up against the
  shut upper ones, and skin of one lid hangs in front of the other's margin. It showed the held-out
  scan's fault (the face's right eye a blank lid) until skin hanging over the opening followed its
  lid whole (docs/import-face.md, "Skin hanging over a shut eye").

- `ict-open-mouth` (development): `ict-identity` with its jaw dropped (the scan's jawOpen at 0.6,
  the lips 2 cm apart at rest): a head scanned or modelled with its mouth open.

- `ict-lowres` (development): the `ict-identity` skin decimated by quadric error
  (`fast_simplification`) to about 2,000 vertices over the whole head and neck: a coarse scan of a
  real person, so the transfer's refining of coarse heads is tried on a head other than MakeHuman's.

- `mediapipe` (held out, added last: measured once, nothing tuned on it): MediaPipe's canonical
  face model, `mediapipe/modules/face_geometry/data/canonical_face_model.obj` of
  https://github.com/google/mediapipe (commit a908d668c730da128dfa8d9f6bd25d519d006692, Apache
  License 2.0), in cm. A 468-vertex face mask (no back of the head) whose eyes and lips stand
  slightly apart but are bridged by triangles: the eye and lip rims are declared as closed loops.
  Its landmarks are the model's own vertices of those names (its published landmark numbering).

Landmarks: the 32 of docs/import-face.md, placed by hand on a frontal picture of each head and
stored here as points in the file's own units; the openings are shortest edge paths through the
landmarks (the lid line from corner to corner through the lid landmarks' middle; a rim loop through
the four eye landmarks). The rig goes on with `puppet import-face --rest-eyes --rest-lips` itself
(a fresh process, as a user runs it); then each pose is simulated and drawn by the product's
renderer as observer.py does for the default face, with the camera putting each head's chin and
forehead landmarks where the default face's are in observer.py's frames (`--framing face`; with
`--framing head` the head is framed by its own extent, as `puppet pose` frames it, and a face mask
then fills the frame and the face detector finds nothing); same crop and classifier.

    nice .venv/bin/python benchmarks/observer_mesh.py [--heads makehuman,makehuman-lowres,nefertiti,ict-identity,ict-lowres] [--save DIR]
                                                      [--framing face|head]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import urllib.request
from pathlib import Path
from collections import Counter
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from observer import SIZE, Observer, perform, score  # noqa: E402
from sim.face.transfer.openings import zip_hole  # noqa: E402

MH_URL = ("https://raw.githubusercontent.com/makehumancommunity/makehuman/"
          "a8bc2d54/makehuman/data/3dobjs/base.obj")
NEF_URL = ("https://raw.githubusercontent.com/odedstein/meshes/835213277571d625722d25880c9c3010c6f45a5a/"
           "objects/nefertiti/nefertiti-lowres.obj")
MP_URL = ("https://raw.githubusercontent.com/google/mediapipe/a908d668c730da128dfa8d9f6bd25d519d006692/"
          "mediapipe/modules/face_geometry/data/canonical_face_model.obj")
LEE_URL = ("https://raw.githubusercontent.com/mrdoob/three.js/"
           "3232c8201a59dc1515500a139bd0e7b75a9e2a42/examples/obj/leeperrysmith/LeePerrySmith.js")

# Landmark points (file units), read off a frontal picture of each head.
MH_POINTS = {
    "forehead_center": [0.0, 7.7076, 1.5164], "glabella": [0.0, 7.3628, 1.5081],
    "brow_inner_l": [0.1116, 7.3937, 1.4843], "brow_inner_r": [-0.1116, 7.3937, 1.4843],
    "brow_mid_l": [0.2827, 7.4153, 1.4295], "brow_mid_r": [-0.2827, 7.4153, 1.4295],
    "brow_outer_l": [0.4618, 7.3839, 1.3443], "brow_outer_r": [-0.4618, 7.3839, 1.3443],
    "eye_inner_l": [0.1766, 7.2858, 1.3987], "eye_inner_r": [-0.1766, 7.2858, 1.3987],
    "eye_outer_l": [0.449, 7.2961, 1.3555], "eye_outer_r": [-0.4427, 7.2955, 1.3608],
    "upper_lid_l": [0.3147, 7.3278, 1.38], "upper_lid_r": [-0.3088, 7.3276, 1.3819],
    "lower_lid_l": [0.3129, 7.2369, 1.4036], "lower_lid_r": [-0.3073, 7.2369, 1.403],
    "nose_bridge": [0.0, 7.2653, 1.513], "nose_tip": [0.0, 6.9031, 1.678],
    "nose_wing_l": [0.1506, 6.9184, 1.5582], "nose_wing_r": [-0.1506, 6.9184, 1.5582],
    "subnasale": [0.0, 6.8229, 1.5978], "upper_lip_top": [0.0, 6.6875, 1.6002],
    "upper_lip_center": [0.0, 6.6235, 1.5707], "lower_lip_center": [0.0, 6.6046, 1.5302],
    "lower_lip_bottom": [0.0, 6.494, 1.5572], "mouth_corner_l": [0.2547, 6.6122, 1.424],
    "mouth_corner_r": [-0.2547, 6.6122, 1.424], "cheek_l": [0.3693, 6.9919, 1.4105],
    "cheek_r": [-0.3693, 6.9919, 1.4105], "chin": [0.0, 6.248, 1.4682],
    "jaw_angle_l": [0.5509, 6.6333, 1.0431], "jaw_angle_r": [-0.5509, 6.6333, 1.0431],
}
LEE_POINTS = {
    "forehead_center": [0.0, 2.3652, 2.1663], "glabella": [0.0, 1.8291, 2.0717],
    "brow_inner_l": [0.2674, 1.9074, 1.9414], "brow_inner_r": [-0.264, 1.8901, 2.0548],
    "brow_mid_l": [0.5304, 1.9554, 2.0136], "brow_mid_r": [-0.5316, 1.9589, 1.9909],
    "brow_outer_l": [0.9169, 1.9139, 1.6993], "brow_outer_r": [-0.8935, 1.8806, 1.9229],
    "eye_inner_l": [0.2222, 1.6989, 1.8526], "eye_inner_r": [-0.4803, 1.6687, 1.8543],
    "eye_outer_l": [0.8158, 1.6427, 1.6678], "eye_outer_r": [-0.9803, 1.6529, 1.7868],
    "upper_lid_l": [0.5046, 1.6626, 1.9519], "upper_lid_r": [-0.7134, 1.6403, 1.9396],
    "lower_lid_l": [0.5053, 1.6164, 1.9405], "lower_lid_r": [-0.718, 1.6051, 1.8844],
    "nose_bridge": [0.0, 1.6731, 2.1475], "nose_tip": [0.0, 1.0964, 2.5575],
    "nose_wing_l": [0.1591, 0.9806, 2.3186], "nose_wing_r": [-0.3269, 0.9946, 2.3829],
    "subnasale": [0.0, 0.8737, 2.2877], "upper_lip_top": [0.0, 0.5545, 2.3172],
    "upper_lip_center": [0.0, 0.4391, 2.226], "lower_lip_center": [0.0, 0.4111, 2.2577],
    "lower_lip_bottom": [0.0, 0.198, 2.2314], "mouth_corner_l": [0.3797, 0.413, 2.0875],
    "mouth_corner_r": [-0.5118, 0.4139, 2.1256], "cheek_l": [0.6564, 1.0176, 1.9076],
    "cheek_r": [-0.6464, 1.0114, 2.0384], "chin": [0.0, -0.5269, 1.9596],
    "jaw_angle_l": [0.8693, -0.0623, 1.426], "jaw_angle_r": [-0.8289, -0.0312, 1.8496],
}

NEF_POINTS = {
    "forehead_center": [3.13, 71.88, 143.24], "glabella": [3.12, 37.88, 156.48],
    "brow_inner_l": [20.13, 41.88, 151.43], "brow_inner_r": [-13.88, 41.88, 151.97],
    "brow_mid_l": [36.12, 46.38, 147.73], "brow_mid_r": [-29.88, 46.37, 149.24],
    "brow_outer_l": [52.12, 40.87, 136.89], "brow_outer_r": [-45.88, 40.88, 140.44],
    "eye_inner_l": [20.13, 22.87, 147.41], "eye_inner_r": [-13.37, 22.37, 148.73],
    "eye_outer_l": [48.12, 24.88, 137.03], "eye_outer_r": [-44.88, 24.88, 137.2],
    "upper_lid_l": [34.12, 29.88, 144.66], "upper_lid_r": [-28.88, 29.37, 149.48],
    "lower_lid_l": [34.13, 20.38, 146.07], "lower_lid_r": [-28.88, 20.38, 144.74],
    "nose_bridge": [3.12, 21.87, 164.42], "nose_tip": [3.12, -8.12, 181.14],
    "nose_wing_l": [19.62, -10.12, 166.37], "nose_wing_r": [-12.88, -10.12, 166.14],
    "subnasale": [3.13, -17.12, 173.7], "upper_lip_top": [3.12, -29.63, 171.56],
    "upper_lip_center": [3.13, -36.13, 168.96], "lower_lip_center": [3.12, -37.62, 167.81],
    "lower_lip_bottom": [3.12, -46.12, 168.29], "mouth_corner_l": [27.12, -35.62, 152.99],
    "mouth_corner_r": [-21.38, -34.62, 154.07], "cheek_l": [39.13, -5.12, 147.22],
    "cheek_r": [-32.88, -5.13, 149.36], "chin": [3.12, -68.12, 166.38],
    "jaw_angle_l": [55.7, -45.8, 110.0], "jaw_angle_r": [-49.8, -45.8, 110.0],
}

MP_POINTS = {
    "forehead_center": [0, 6.545, 5.027], "glabella": [0, 4.886, 5.385],
    "brow_inner_l": [1.396, 5.012, 5.316], "brow_inner_r": [-1.396, 5.012, 5.316],
    "brow_mid_l": [3.987, 5.109, 4.466], "brow_mid_r": [-3.987, 5.109, 4.466],
    "brow_outer_l": [5.721, 4.255, 2.831], "brow_outer_r": [-5.721, 4.255, 2.831],
    "eye_inner_l": [1.856, 2.585, 3.758], "eye_inner_r": [-1.856, 2.585, 3.758],
    "eye_outer_l": [4.446, 2.664, 3.173], "eye_outer_r": [-4.446, 2.664, 3.173],
    "upper_lid_l": [3.177, 2.964, 3.877], "upper_lid_r": [-3.177, 2.964, 3.877],
    "lower_lid_l": [3.177, 2.294, 3.776], "lower_lid_r": [-3.177, 2.294, 3.776],
    "nose_bridge": [0, 2.473, 5.789], "nose_tip": [0, -0.4632, 7.587],
    "nose_wing_l": [1.786, -0.9783, 4.85], "nose_wing_r": [-1.786, -0.9783, 4.85],
    "subnasale": [0, -2.089, 6.058], "upper_lip_top": [0, -3.406, 5.98],
    "upper_lip_center": [0, -3.994, 5.219], "lower_lip_center": [0, -4.542, 5.405],
    "lower_lip_bottom": [0, -5.365, 5.535], "mouth_corner_l": [2.456, -4.343, 4.284],
    "mouth_corner_r": [-2.456, -4.343, 4.284], "cheek_l": [4.766, -0.7016, 3.535],
    "cheek_r": [-4.766, -0.7016, 3.535], "chin": [0, -9.403, 4.264], "jaw_angle_l": [6.72, -4.789, -1.745],
    "jaw_angle_r": [-6.72, -4.789, -1.745],
}


def meshes_folder(arg: str | None) -> Path:
    return Path(arg or os.environ.get("PUPPET_MESHES", Path.home() / ".cache" / "facepuppet" / "meshes"))


def fetch_once(folder: Path, name: str, url: str) -> Path:
    """The source file in `folder`, downloaded from its public address when it is not there."""
    path = folder / name
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".part")
        with urllib.request.urlopen(url, timeout=120) as r:  # noqa: S310 - a fixed public address
            tmp.write_bytes(r.read())
        tmp.replace(path)
    return path


def load_makehuman(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The "body" group of the MakeHuman base mesh, triangulated, cut 3.2 units below the crown."""
    verts, tris, group = [], [], None
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f ") and group == "body":
            idx = [int(p.split("/")[0]) - 1 for p in line.split()[1:]]
            tris += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    v, t = np.asarray(verts), np.asarray(tris)
    cut = v[np.unique(t), 1].max() - 3.2
    return _compact(v, t[(v[t][:, :, 1] > cut).all(axis=1)])


def load_makehuman_mask(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The MakeHuman head cut to a face mask (no crown, ears, back of the head or neck), as a face
    tracker's canonical mesh is: the skin in front of the jaw angles, from under the chin to the
    hairline."""
    v, t = load_makehuman(path)
    keep = (v[:, 2] > 1.12) & (v[:, 1] > 6.17) & (v[:, 1] < 7.86)
    return _compact(v, t[keep[t].all(axis=1)])


LOWRES_VERTICES = 470  # about MediaPipe's canonical face mesh's 468


def load_makehuman_lowres(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The MakeHuman face mask decimated (quadric error, `fast_simplification`) to about
    LOWRES_VERTICES vertices, the resolution of a face tracker's canonical mesh: a coarse mask with
    no head round it, no eyeballs and no mouth inside once its rims are opened."""
    import fast_simplification

    v, t = load_makehuman_mask(path)
    keep = 1.0 - LOWRES_VERTICES / len(v)
    vo, fo = fast_simplification.simplify(v.astype(np.float32), t.astype(np.int32), target_reduction=keep)
    return _compact(np.asarray(vo, float), np.asarray(fo, np.int64))


def load_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A plain OBJ (polygons fanned into triangles), the texture and normal indices skipped."""
    verts, tris = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            idx = [int(p.split("/")[0]) - 1 for p in line.split()[1:]]
            tris += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    return _compact(np.asarray(verts), np.asarray(tris))


def load_three_json(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A three.js JSON model (format 2): vertices and faces (quads split), the per-face extras skipped."""
    text = path.read_text()
    model = json.loads(text[text.index("{"):text.rindex("}") + 1])
    v = np.asarray(model["vertices"], float).reshape(-1, 3)
    f, i, tris = model["faces"], 0, []
    n_uv = len(model.get("uvs", [])) or 1
    while i < len(f):
        kind = f[i]
        n = 4 if kind & 1 else 3
        idx = f[i + 1:i + 1 + n]
        i += 1 + n
        i += (1 if kind & 2 else 0) + (n_uv if kind & 4 else 0) + (n * n_uv if kind & 8 else 0)
        i += (1 if kind & 16 else 0) + (n if kind & 32 else 0) + (1 if kind & 64 else 0) + (n if kind & 128 else 0)
        tris += [[idx[0], idx[1], idx[2]], [idx[0], idx[2], idx[3]]] if n == 4 else [idx]
    return v, np.asarray(tris)


def _compact(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.unique(t)
    remap = -np.ones(len(v), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[t]


def edge_path(v: np.ndarray, t: np.ndarray, points: list[np.ndarray], closed: bool = False) -> list[int]:
    """The shortest path along mesh edges through the vertices nearest `points` (a loop if closed)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree

    e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    g = coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(len(v),) * 2).tocsr()
    stops = [int(i) for i in cKDTree(v).query(np.asarray(points))[1]]
    if closed:
        stops.append(stops[0])
    path: list[int] = [stops[0]]
    for a, b in zip(stops[:-1], stops[1:]):
        leg_graph = g
        if closed:  # a loop passes each vertex once: later legs go round the earlier ones
            used = np.zeros(len(v), bool)
            used[[i for i in path if i not in (a, b)]] = True
            ok = ~used[e].any(axis=1)
            leg_graph = coo_matrix((np.r_[w[ok], w[ok]], (np.r_[e[ok, 0], e[ok, 1]], np.r_[e[ok, 1], e[ok, 0]])),
                                   shape=(len(v),) * 2).tocsr()
        _, pred = dijkstra(leg_graph, indices=a, return_predecessors=True)
        leg = [b]
        while leg[-1] != a:
            leg.append(int(pred[leg[-1]]))
        path += leg[::-1][1:]
    return path[:-1] if closed else path


def openings(v: np.ndarray, t: np.ndarray, pts: dict[str, list[float]], eyes_open: bool,
             lips_open: bool) -> dict[str, list[int]]:
    """Declared openings: rim loops round open eyes and parted lips (what they enclose is removed:
    a mouth's lining, a carved or fused eyeball), the lip and lid lines as slits where they are shut."""
    p = {k: np.asarray(x) for k, x in pts.items()}
    if lips_open:  # a modelled head: the lips part at the front, the mouth's lining closes behind them
        out = {"mouth": edge_path(v, t, [p["mouth_corner_r"], p["upper_lip_center"], p["mouth_corner_l"],
                                         p["lower_lip_center"]], closed=True)}
    else:
        out = {"mouth": edge_path(v, t, [p["mouth_corner_r"], 0.5 * (p["upper_lip_center"] + p["lower_lip_center"]),
                                         p["mouth_corner_l"]])}
    for s in "lr":
        inner, outer, up, low = (p[f"{n}_{s}"] for n in ("eye_inner", "eye_outer", "upper_lid", "lower_lid"))
        if eyes_open:
            out[f"eye_{s}"] = edge_path(v, t, [inner, up, outer, low], closed=True)
        else:
            out[f"eye_{s}"] = edge_path(v, t, [inner, 0.5 * (up + low), outer])
    return out


ICT_SEED = 7  # the development identity of the scanned head (`--face ict?identity=7`)


def load_ict_identity(_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The scanned head's skin (face and head-neck parts, no eyes, teeth or mouth socket) with the
    identity of `seed`, as a third party would export it: an open-eyed scan with its own lips
    meeting at rest, the eye and mouth openings left as holes."""
    return _compact(*_ict_skin(shut=False))


def _ict_skin(shut: bool, squeezed: bool = False, jaw: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The identity's skin vertices (the scan's order, all parts) and the skin's triangles; `shut`:
    with the scan's own blinks (eyeBlink_L and _R at 1) applied; `squeezed`: and its cheeks raised
    (cheekSquint_L and _R at 1), the eyes squeezed shut; `jaw`: the scan's jawOpen at that weight."""
    from puppet.faces import seed_identity
    from sim.face.scan.data import scan_data

    d = scan_data()
    v = d.neutral + d.identity_delta(np.asarray(seed_identity(ICT_SEED)))
    if shut:
        v = v + d.expression("eyeBlink_L") + d.expression("eyeBlink_R")
    if squeezed:
        v = v + d.expression("cheekSquint_L") + d.expression("cheekSquint_R")
    if jaw:
        v = v + jaw * d.expression("jawOpen")
    return v, np.concatenate([d.triangles("face"), d.triangles("head_neck")])


def ict_points(shut: bool = False, squeezed: bool = False, jaw: float = 0.0) -> dict[str, list[float]]:
    """The scanned head's own landmarks (its vertex numbers, `sim/face/scan/landmarks.json`, all in
    the face part, which the compaction keeps in place) as points on the identity's skin."""
    lm = json.loads((ROOT / "sim" / "face" / "scan" / "landmarks.json").read_text())
    v, _ = _ict_skin(shut, squeezed, jaw)
    return {k: [float(x) for x in v[i]] for k, i in lm.items()}


ICT_LOWRES_VERTICES = 2000


def load_ict_lowres(_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The scanned identity's skin (`load_ict_identity`) decimated by quadric error
    (`fast_simplification`) to about ICT_LOWRES_VERTICES vertices over the whole head and neck (about
    a third of them on the face): a coarse scan of a real person, to try the coarse-mesh path of the
    transfer on a head other than MakeHuman's."""
    import fast_simplification

    v, t = load_ict_identity(_path)
    keep = 1.0 - ICT_LOWRES_VERTICES / len(v)
    vo, fo = fast_simplification.simplify(v.astype(np.float32), t.astype(np.int32), target_reduction=keep)
    return _compact(np.asarray(vo, float), np.asarray(fo, np.int64))


def load_ict_shut(_path: Path, squeezed: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The identity scanned with its eyes shut, as a scan with closed lids comes: the blinked
    lids' rims (which meet) joined by a strip of triangles, so each eye is one closed surface, to
    be declared as a lid line (a slit) like any shut scan's; `squeezed`: the cheeks raised too."""
    v, t = _compact(*_ict_skin(shut=True, squeezed=squeezed))
    points = ict_points(shut=True, squeezed=squeezed)
    new: list[list[int]] = []
    for loop in _boundary_loops(t):
        for s in "lr":
            centre = 0.5 * (np.asarray(points[f"eye_inner_{s}"]) + np.asarray(points[f"eye_outer_{s}"]))
            if len(loop) > 10 and np.linalg.norm(v[loop].mean(axis=0) - centre) < 1.0:
                new += zip_hole(v, np.asarray(loop))
    directed = {(x[k], x[(k + 1) % 3]) for x in t.tolist() for k in range(3)}
    uses = Counter(tuple(sorted(e)) for x in t.tolist() for e in ((x[0], x[1]), (x[1], x[2]), (x[2], x[0])))
    added = []
    for x in new:
        es = [tuple(sorted(e)) for e in ((x[0], x[1]), (x[1], x[2]), (x[2], x[0]))]
        if len(set(x)) < 3 or any(uses[e] >= 2 for e in es):
            continue  # a degenerate corner, or an edge that already has its two triangles
        if any((x[k], x[(k + 1) % 3]) in directed for k in range(3)):
            x = x[::-1]  # wound as its neighbours are
        uses.update(es)
        directed.update((x[k], x[(k + 1) % 3]) for k in range(3))
        added.append(x)
    return v, np.concatenate([t, np.asarray(added, dtype=t.dtype).reshape(-1, 3)])


ICT_OPEN_JAW = 0.6  # the scan's jawOpen for the head modelled with its mouth open


def load_ict_open_mouth(_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The identity's skin (`load_ict_identity`) with its jaw dropped (jawOpen at ICT_OPEN_JAW): a
    head scanned or modelled with its mouth open at rest, the lips 2 cm apart."""
    return _compact(*_ict_skin(shut=False, jaw=ICT_OPEN_JAW))


def load_ict_squeezed(_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """`load_ict_shut` with the eyes squeezed shut (the cheeks raised, pushing the lower lids up)."""
    return load_ict_shut(_path, squeezed=True)


def _boundary_loops(t: np.ndarray) -> list[list[int]]:
    """The mesh's holes: each boundary loop's vertices in order."""
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    nb: dict[int, list[int]] = {}
    for a, b in u[c == 1].tolist():
        nb.setdefault(a, []).append(b)
        nb.setdefault(b, []).append(a)
    loops, seen = [], set()
    for start in nb:
        if start in seen:
            continue
        loop, prev, cur = [start], -1, start
        seen.add(start)
        while True:
            nxt = [x for x in nb[cur] if x != prev and x not in seen]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            loop.append(cur)
            seen.add(cur)
        loops.append(loop)
    return loops



def past_corner(v: np.ndarray, t: np.ndarray, path: list[int]) -> list[int]:
    """A lid line (inner corner first) traced one edge further at the inner corner, to the corner's
    neighbour furthest towards the nose and up, as a line snapped to a scan's vertices can start."""
    inner, outer = path[0], path[-1]
    axis = v[outer] - v[inner]
    ring = [int(n) for n in np.unique(t[(t == inner).any(axis=1)]) if n not in path]
    score = [(v[n] - v[inner]) @ axis / (axis @ axis) - (v[n, 1] - v[inner, 1]) for n in ring]
    return [ring[int(np.argmin(score))], *path]


HEADS: dict[str, dict[str, Any]] = {
    "ict-identity": {"file": None, "url": None, "load": load_ict_identity, "points": None,
                     "eyes_open": True, "lips_open": None, "role": "development"},
    "ict-lowres": {"file": None, "url": None, "load": load_ict_lowres, "points": None,
                   "eyes_open": True, "lips_open": None, "role": "development"},
    "ict-shut": {"file": None, "url": None, "load": load_ict_shut, "points": None,
                 "eyes_open": False, "lips_open": None, "role": "development"},
    "ict-shut-corner": {"file": None, "url": None, "load": load_ict_shut, "points": None, "eyes_open": False,
                        "lips_open": None, "role": "development", "past_corner": True},
    "ict-shut-squeezed": {"file": None, "url": None, "load": load_ict_squeezed, "points": None,
                          "eyes_open": False, "lips_open": None, "role": "development", "squeezed": True},
    "ict-open-mouth": {"file": None, "url": None, "load": load_ict_open_mouth, "points": None,
                       "eyes_open": True, "lips_open": None, "role": "development", "jaw": ICT_OPEN_JAW},
    "makehuman": {"file": "makehuman_base.obj", "url": MH_URL, "load": load_makehuman, "points": MH_POINTS,
                  "eyes_open": True, "lips_open": True, "role": "development"},
    "makehuman-mask": {"file": "makehuman_base.obj", "url": MH_URL, "load": load_makehuman_mask,
                       "points": MH_POINTS, "eyes_open": True, "lips_open": True, "role": "development"},
    "makehuman-lowres": {"file": "makehuman_base.obj", "url": MH_URL, "load": load_makehuman_lowres,
                         "points": MH_POINTS, "eyes_open": True, "lips_open": True, "role": "development"},
    "nefertiti": {"file": "nefertiti-lowres.obj", "url": NEF_URL, "load": load_obj, "points": NEF_POINTS,
                  "eyes_open": True, "lips_open": False, "role": "development"},
    "leeperrysmith": {"file": "LeePerrySmith.js", "url": LEE_URL, "load": load_three_json, "points": LEE_POINTS,
                      "eyes_open": False, "lips_open": False, "role": "held out"},
    "mediapipe": {"file": "canonical_face_model.obj", "url": MP_URL, "load": load_obj, "points": MP_POINTS,
                  "eyes_open": True, "lips_open": True, "role": "held out"},
}


def import_head(name: str, folder: Path, work: Path) -> Path:
    """Write the head and its landmark file, run `puppet import-face` on them; the rig's path."""
    import trimesh

    spec = HEADS[name]
    loader: Callable[[Path], tuple[np.ndarray, np.ndarray]] = spec["load"]
    v, t = loader(fetch_once(folder, spec["file"], spec["url"]) if spec["file"] else folder)
    trimesh.Trimesh(v, t, process=False).export(work / f"{name}.obj")
    if spec["points"] is None:  # the scanned head: its mouth (and open eyes) are holes the importer finds
        pts = ict_points(shut=not spec["eyes_open"], squeezed=bool(spec.get("squeezed")), jaw=spec.get("jaw", 0.0))
        lm: dict[str, Any] = {"landmarks": pts}
        if not spec["eyes_open"]:
            lm["openings"] = {k: p for k, p in openings(v, t, pts, False, False).items() if k != "mouth"}
            if spec.get("past_corner"):
                lm["openings"] = {k: past_corner(v, t, p) for k, p in lm["openings"].items()}
    else:
        lm = {"landmarks": spec["points"],
              "openings": openings(v, t, spec["points"], spec["eyes_open"], spec["lips_open"])}
    (work / f"{name}.json").write_text(json.dumps(lm))
    rig = work / f"{name}.npz"
    cmd = [sys.executable, "-m", "puppet", "import-face", str(work / f"{name}.obj"), "--landmarks",
           str(work / f"{name}.json"), "--out", str(rig), "--rest-eyes", "--rest-lips"]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if run.returncode:
        raise SystemExit(f"import-face failed on {name}: {run.stderr.strip()}")
    return rig


def _face_box(model: Any) -> tuple[np.ndarray, np.ndarray]:
    """(middle of chin and forehead_center, chin-to-forehead height) of a face at rest (cm)."""
    r, lm = np.asarray(model.rest, float), model.mesh.landmarks
    chin, top = r[lm["chin"]], r[lm["forehead_center"]]
    return 0.5 * (chin + top), np.full(3, top[1] - chin[1])


def default_framing() -> tuple[np.ndarray, np.ndarray]:
    """The box observer.py's camera frames on the default face, relative to its face (`_face_box`):
    (lo, hi) offsets from the face's middle in units of its height."""
    from puppet.face_cache import scan_model
    from render.offscreen import OffscreenRenderer

    model = scan_model(None)
    mid, span = _face_box(model)
    with OffscreenRenderer(model, (SIZE, SIZE), supersample=2) as off:
        cam = off.renderer.camera
        return (cam.lo - mid) / span, (cam.hi - mid) / span


def head_frames(rig_path: Path, names: list[str], framing: tuple[np.ndarray, np.ndarray] | None = None
                ) -> dict[str, np.ndarray]:
    """{pose: grayscale frame} of the imported head, drawn as observer.py draws the default face;
    `framing` (from `default_framing`): the camera puts the head's chin and forehead where the
    default face's are in its frames (else it frames the head as `puppet pose` does)."""
    from render.offscreen import OffscreenRenderer
    from sim.build import compile_model
    from sim.rig import load_rig

    model = compile_model(load_rig(rig_path))
    mid, span = _face_box(model)
    out: dict[str, np.ndarray] = {}
    for name in names:
        state, _ = perform(model, None if name == "neutral" else name)
        with OffscreenRenderer(model, (SIZE, SIZE), supersample=2) as off:
            if framing is not None:
                off.renderer.camera.fit(mid + framing[0] * span, mid + framing[1] * span)
            off.renderer.camera.scale = 0.62
            rgb = off.render_frame(state, record=False).astype(np.float64)
        out[name] = np.clip(rgb @ np.array([0.299, 0.587, 0.114]), 0, 255).astype(np.uint8)
    return out


def main(argv: list[str] | None = None) -> int:
    from sim.facs import EXPRESSIONS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--heads", default="makehuman", help="comma-separated: " + ", ".join(HEADS))
    ap.add_argument("--meshes", default=None, help="folder of the source files (downloaded when missing)")
    ap.add_argument("--only", default="", help="comma-separated poses (default: neutral and the seven presets)")
    ap.add_argument("--save", default="", help="folder for each frame as PNG")
    ap.add_argument("--framing", default="face", choices=("face", "head"),
                    help="face (default): each head's chin and forehead where the default face's are in "
                         "observer.py's frames; head: the head framed as `puppet pose` frames it")
    args = ap.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or ["neutral", *EXPRESSIONS]
    obs = Observer()
    framing = default_framing() if args.framing == "face" else None
    with tempfile.TemporaryDirectory() as tmp:
        for head in [h for h in args.heads.split(",") if h]:
            rig = import_head(head, meshes_folder(args.meshes), Path(tmp))
            score(obs, head_frames(rig, names, framing), f"{head} ({HEADS[head]['role']})", args.save)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
