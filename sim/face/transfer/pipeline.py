"""Transfer a reference rig onto a new head (seed 003 section 3.2, extended to the whole rig):
orient the head from its landmarks, fit and unroll one cylinder per face, pin the reference's
characteristic points onto the new face's, relax (eq 8), cast back, and carry every rig element."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from sim.model import FaceMesh, FaceRig, Muscle, SheetMuscle
from sim.face.transfer.carry import SurfaceMap, carry_muscle, carry_wrinkle, cover_sheet
from sim.face.transfer.cylinder import Cylinder, fit_cylinder
from sim.face.transfer.flatten import CylinderChart, flat_triangulation, hidden_under, project_back
from sim.face.transfer.frame import Similarity, fit_similarity, landmark_axes, rotation_angle
from sim.face.transfer.geometry import (closest_points, edge_use_counts, in_polygon, locate_2d, outer_loop,
                                   split_pinched, triangle_normals, unique_edges)
from sim.face.transfer.eyes import seat_eyes
from sim.face.transfer.forces import match_forces
from sim.face.transfer.lids import open_lids
from sim.face.transfer.lower_lid import place_lower_lids
from sim.face.transfer.landmarks import LANDMARK_NAMES, LandmarkFile, TransferError, require
from sim.face.transfer.meshfile import HeadMesh
from sim.face.transfer.mouth import close_jaw, rest_lips
from sim.face.transfer.openings import (CORNERS, cut_slit, find_openings, is_closed_path, is_hole_loop, open_loop,
                                       slit_corners)
from sim.face.transfer.refine import edge_scale, levels_needed, subdivide
from sim.face.transfer.relax import Relaxation, relax_mask
from sim.face.transfer.skin import lid_support

FloatArray = np.ndarray
IntArray = np.ndarray
FORWARD = np.array([0.0, 0.0, 1.0])
UP = np.array([0.0, 1.0, 0.0])
IMPORTED_PRESETS = "imported-3"  # sim.facs.FACE_EXPRESSIONS' intensities for a head without teeth
CAVITY_DEPTH = 0.015  # of the landmark region's radius (~1 mm on an adult): a layer this far under
# the outermost skin seen along the cylinder's radius is the inside of the mouth, a socket or a nostril


@dataclass(frozen=True)
class TransferOptions:
    """Tolerances, all relative to the outer-eye-corner distance (about 9 cm on an adult).
    region: landmarks' neighbourhood that both cylinders are fitted to; landmark_offset: how far a
    landmark point may lie off the surface; shape: RMS landmark misfit after the best similarity
    above which the layout is not a face's; frame_angle: degrees the fitted rotation may differ
    from the one read off chin/forehead, sides and nose; area_stiffness: weight of the anti-fold
    area term added to eq 8's springs (0 = the paper's springs alone); integrator: the rig's
    `FaceRig.integrator` (implicit: its fold guard keeps a foreign mesh's skin from turning over);
    seat_eyes: bring each eye's opening to a resting eye's and seat the eyeball behind it
    (sim.face.transfer.eyes) rather than where the skin correspondence carries it; lid_support:
    fade the skin's normal support out on lids turned away from the front (sim.face.transfer.skin);
    rest_lips: bring lips that stand apart at rest to the reference's gap (sim.face.transfer.mouth);
    cover_sheets: widen a channel's one sheet muscle until it covers the skin the reference's pulls on
    (sim.face.transfer.carry.cover_sheet; off here so the scanned head's rig, made by this
    transfer, stays as shipped; `puppet import-face` turns it on); match_forces: scale each
    channel's muscles so they pull as hard in all as the reference's (sim.face.transfer.forces;
    off here for the same reason, on in `puppet import-face`); refine: split the triangles of a
    head whose edges near the landmarks are over 2.5 x the reference's (sim.face.transfer.refine)
    until they are within 1.5 x (off here for the same reason, on in `puppet import-face`);
    place_lower_lids: rebuild the lower lid's tightener (AU7) on the head's own lower lid, after the
    lids are brought to rest, as the reference's sits on its lid (sim.face.transfer.lower_lid; off
    here for the same reason, on in `puppet import-face`)."""

    region: float = 0.6
    landmark_offset: float = 0.1
    shape: float = 0.2
    frame_angle: float = 35.0
    area_stiffness: float = 10.0
    integrator: str = "implicit"
    seat_eyes: bool = False
    lid_support: bool = True
    rest_lips: bool = False
    cover_sheets: bool = False
    match_forces: bool = False
    refine: bool = False
    place_lower_lids: bool = False


@dataclass
class Transfer:
    """A transferred rig and the figures its report shows (lengths in cm, project frame)."""

    rig: FaceRig
    similarity: Similarity
    reference_cylinder: Cylinder
    new_cylinder: Cylinder
    relaxation: Relaxation
    shape_residuals: dict[str, float]
    landmark_errors: dict[str, float]
    ray_misses: int
    folded_triangles: int
    outside_vertices: int
    flipped_winding: bool
    dropped_vertices: int
    notes: list[str] = field(default_factory=list)
    dense: str = ""  # what to change when the head is too dense to simulate live (`dense_warning`)


DENSE = 8.0  # x the reference's vertices: a head denser than this is too slow to simulate live


def dense_warning(vertices: int, reference_vertices: int) -> str:
    """One line for a head whose mesh is much denser than the reference's, "" otherwise. The skin's
    step costs about in proportion to its vertices: the default (scanned) face simulates 6,706
    vertices in about a seventh of a 60 Hz frame, and a head over DENSE x the reference's at
    resolution 1 (21,672) has more than three times as many. The scanned identity subdivided once
    (45,254 vertices) took 192 s to import. The rig is still written: offline work (`puppet pose`,
    `puppet render`) needs no live rate."""
    ratio = vertices / max(reference_vertices, 1)
    if ratio <= DENSE:
        return ""
    want = int(round(2 * reference_vertices, -3))
    return (f"the head has {vertices} vertices, {ratio:.1f} x the reference face's {reference_vertices}: each "
            f"simulation step costs about as much more, too slow for live use; decimate the mesh to about "
            f"{want} vertices (e.g. quadric decimation in Blender or MeshLab) and import it again")


def _carry(smap: SurfaceMap, parts: tuple[Muscle, ...], opt: TransferOptions) -> tuple[Muscle, ...]:
    """One channel's reference muscles on the new head (`carry_muscle`). When asked, a channel
    whose one part is a sheet is also made to cover its skin (`cover_sheet`); a channel of many
    sheets (the lids' strips) tiles its skin with them, and a strip widened would overlap its
    neighbours."""
    out = tuple(carry_muscle(smap, m) for m in parts)
    if opt.cover_sheets and len(parts) == 1 and isinstance(parts[0], SheetMuscle):
        return (cover_sheet(smap, parts[0], out[0]),)  # type: ignore[arg-type]
    return out


def _resolve(lf: LandmarkFile, head: HeadMesh, names: list[str],
             opt: TransferOptions) -> tuple[dict[str, FloatArray], dict[str, int]]:
    """Landmark points on the welded mesh (file units) and their nearest vertices."""
    pts: dict[str, FloatArray] = {}
    for n in names:
        e = lf.entries[n]
        if isinstance(e, (int, np.integer)):
            if not 0 <= e < len(head.file_to_vertex):
                raise TransferError(f"{lf.path}: landmark {n!r} is vertex {e}, but {head.path} has "
                                    f"{len(head.file_to_vertex)} vertices (indices are 0-based)")
            pts[n] = head.vertices[head.file_to_vertex[e]]
        else:
            pts[n] = np.asarray(e, float)
    width = float(np.linalg.norm(pts["eye_outer_l"] - pts["eye_outer_r"]))
    if width <= 0:
        raise TransferError(f"{lf.path}: eye_outer_l and eye_outer_r coincide; this is not a face")
    raw = np.stack([pts[n] for n in names])
    foot, tri, bary, dist = closest_points(raw, head.vertices, head.triangles)
    for n, d in zip(names, dist):
        if d > opt.landmark_offset * width:
            raise TransferError(
                f"{lf.path}: landmark {n!r} lies {d:.3g} units off the surface of {head.path} "
                f"(limit {opt.landmark_offset * width:.3g}); check its coordinates and units")
    corners = head.triangles[tri]
    vid = corners[np.arange(len(names)), bary.argmax(axis=1)]
    return {n: foot[i] for i, n in enumerate(names)}, {n: int(vid[i]) for i, n in enumerate(names)}


def _orient(pts: dict[str, FloatArray], ref: dict[str, FloatArray], names: list[str],
            lf: LandmarkFile, opt: TransferOptions) -> tuple[Similarity, dict[str, float]]:
    """The file -> project frame similarity, refusing mirrored and non-face layouts; also each
    landmark's distance from the reference's after the fit (cm)."""
    src = np.stack([pts[n] for n in names])
    dst = np.stack([ref[n] for n in names])
    limit = opt.shape * float(np.linalg.norm(ref["eye_outer_l"] - ref["eye_outer_r"]))
    sim = fit_similarity(src, dst)
    resid = np.linalg.norm(sim.apply(src) - dst, axis=1)
    if np.sqrt(np.mean(resid ** 2)) > limit:
        mirror = fit_similarity(src * [-1.0, 1.0, 1.0], dst)
        if np.sqrt(np.mean(np.linalg.norm(mirror.apply(src * [-1.0, 1.0, 1.0]) - dst, axis=1) ** 2)) <= limit:
            raise TransferError(f"{lf.path}: the landmarks fit a face only when mirrored: _l/_r must "
                                "name the face's own left/right (or the mesh is mirrored)")
        worst = names[int(resid.argmax())]
        raise TransferError(f"{lf.path}: the landmarks do not have the layout of a face (worst: "
                            f"{worst}, {resid.max():.1f} cm off after the best fit)")
    if rotation_angle(sim.rotation, landmark_axes(pts)) > opt.frame_angle:
        raise TransferError(f"{lf.path}: the landmarks do not have the layout of a face (chin, "
                            "forehead and sides disagree with the best fit on the head's orientation)")
    return sim, {n: float(r) for n, r in zip(names, resid)}


def _face_component(vertices: FloatArray, triangles: IntArray, vids: list[int]) -> tuple[FloatArray, IntArray, IntArray]:
    """Keep the connected surface that holds the landmarks; eyeballs, teeth and other separate
    parts are dropped. Returns (vertices, triangles, old -> new index with -1 for dropped)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(vertices)
    e = unique_edges(triangles)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    main = np.bincount(label[vids]).argmax()
    keep = label == main
    remap = -np.ones(n, dtype=np.int64)
    remap[keep] = np.arange(keep.sum())
    tri = triangles[keep[triangles].all(axis=1)]
    return vertices[keep], remap[tri].astype(np.int32), remap


def _region(vertices: FloatArray, landmark_pts: FloatArray, radius: float) -> np.ndarray:
    """Vertices within `radius` of a landmark: the part of a face both cylinders are fitted to."""
    d, _ = cKDTree(landmark_pts).query(vertices)
    return d < radius


def _file_vertex(head: HeadMesh, sim: Similarity, point: FloatArray) -> int:
    """The file's index (0-based, as the landmark file counts) of the vertex at `point` (project
    frame): the file's first vertex welded to the head's vertex nearest it."""
    welded = int(np.argmin(np.linalg.norm(head.vertices - sim.invert(point), axis=1)))
    return int(np.flatnonzero(np.asarray(head.file_to_vertex) == welded)[0])


def _check_surface(vertices: FloatArray, triangles: IntArray, region: np.ndarray, path: str,
                   file_vertex: Callable[[FloatArray], int] | None = None) -> bool:
    """The face region must be an oriented manifold; returns True when the whole mesh's winding
    had to be flipped so normals point out of the skin. `file_vertex`: a point's vertex in the
    file's own numbering, for the message (welding, dropped parts and cuts renumber the mesh; the
    message named the renumbered vertices, which the file does not have)."""
    tri = triangles[region[triangles].all(axis=1)]
    if len(tri) == 0:
        raise TransferError(f"{path}: no surface near the landmarks; this is not a face mesh")
    edges, counts = edge_use_counts(tri)
    if (counts > 2).any():
        a, b = edges[np.argmax(counts > 2)]
        if file_vertex is not None:
            a, b = file_vertex(vertices[a]), file_vertex(vertices[b])
        n = int((counts > 2).sum())
        raise TransferError(f"{path}: the face is not manifold ({n} edge{'s' if n > 1 else ''} shared by 3 or more "
                            f"triangles, e.g. between vertices {a} and {b}, 0-based in the file); repair the mesh")
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) < len(directed):
        raise TransferError(f"{path}: the face's triangles are not consistently oriented; "
                            "repair the mesh (e.g. recalculate normals)")
    return float(triangle_normals(vertices, tri).sum(axis=0) @ FORWARD) < 0


def _flat_fit(ref_uv: FloatArray, new_uv: FloatArray) -> FloatArray:
    """Least-squares 2D affine map (3, 2) from reference to new flat landmarks."""
    a = np.column_stack([ref_uv, np.ones(len(ref_uv))])
    return np.linalg.lstsq(a, new_uv, rcond=None)[0]


def _signed_areas(p: FloatArray, tri: IntArray) -> FloatArray:
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


@dataclass
class _Head:
    """The new head in the project frame, ready for the transfer (indices after welding, dropping
    separate parts and cutting declared slits)."""

    vertices: FloatArray
    triangles: IntArray
    landmarks: dict[str, FloatArray]
    landmark_vertex: dict[str, int]
    openings: dict[str, IntArray]
    cut: list[IntArray]
    flipped: bool
    dropped: int
    split: int = 0  # vertices where the border touched itself, split (geometry.split_pinched)
    corners: dict[str, float] = field(default_factory=dict)  # corner landmarks put on a cut's ends: how far (cm)


def _bring_in(head: HeadMesh, lf: LandmarkFile, names: list[str], pts: dict[str, FloatArray],
              vids: dict[str, int], sim: Similarity, region_radius: float) -> _Head:
    """Open declared closed loops, keep the landmarked surface, move it into the project frame,
    cut declared lip/lid lines, check the face is an oriented manifold (flipping inward winding)."""
    declared = _declared(lf, head)
    tris = head.triangles
    for key, loop in declared.items():  # a declared closed loop: open what it encloses
        if is_closed_path(loop, tris) and not is_hole_loop(loop, tris):
            tris = open_loop(tris, loop, key, lf.path)
    verts, tris, remap = _face_component(head.vertices, tris, list(vids.values()))
    declared = {k: remap[v] for k, v in declared.items()}
    for key, loop in declared.items():
        if (loop < 0).any():
            raise TransferError(f"{lf.path}: opening {key!r} is not on the face surface of {head.path}")
    verts = sim.apply(verts)
    lm_new = {n: sim.apply(pts[n]) for n in names}
    lm_vid = {n: int(remap[vids[n]]) for n in names}
    cut: list[IntArray] = []
    corners: dict[str, float] = {}
    for key, path in list(declared.items()):
        if not is_hole_loop(path, tris):
            verts, tris, declared[key], lower = cut_slit(verts, tris, path, UP, key, lf.path)
            cut.append(declared[key])
            names_at = CORNERS[key]  # the lids (lips) meet at the cut's ends: the corners are there
            ends = slit_corners(verts, (int(path[0]), int(path[-1])), tuple(lm_new[n] for n in names_at))
            for n, end in zip(names_at, ends):
                if lm_vid[n] != end:
                    corners[n] = float(np.linalg.norm(verts[end] - lm_new[n]))
                    lm_vid[n], lm_new[n] = end, verts[end].copy()
            for n in names:  # a lower-lip or lower-lid landmark on the cut moves to the lower copy
                if n.startswith("lower_") and lm_vid[n] in lower:
                    lm_vid[n] = lower[lm_vid[n]]
    region = _region(verts, np.stack([lm_new[n] for n in names]), region_radius)
    flipped = _check_surface(verts, tris, region, head.path, lambda p: _file_vertex(head, sim, p))
    if flipped:
        tris = tris[:, ::-1].copy()
    # a border touching itself near the face (lips modelled meeting at one point) that an opening's
    # loop walked twice is split there: the lip rows held that vertex twice, and building the rig's
    # integrator (`puppet pose --rig`) stopped with a traceback
    verts, tris, pinched = split_pinched(verts, tris, region)
    return _Head(verts, tris, lm_new, lm_vid, declared, cut, flipped, int((remap < 0).sum()), len(pinched), corners)


def transfer_rig(
    reference: FaceRig,
    head: HeadMesh,
    landmarks: LandmarkFile,
    name: str = "imported",
    options: TransferOptions | None = None,
) -> Transfer:
    """Make a rig for `head` from `reference` (see docs/import-face.md)."""
    opt = options or TransferOptions()
    ref = reference.mesh
    names = [n for n in LANDMARK_NAMES if n in ref.landmarks]
    require(landmarks, names)
    pts, vids = _resolve(landmarks, head, names, opt)
    ref_pts = {n: ref.landmark(n) for n in names}
    sim, shape = _orient(pts, ref_pts, names, landmarks, opt)
    radius = opt.region * float(np.linalg.norm(ref_pts["eye_outer_l"] - ref_pts["eye_outer_r"]))
    new = _bring_in(head, landmarks, names, pts, vids, sim, radius)
    refined = _refine(new, ref, ref_pts, landmarks, names, radius) if opt.refine else None
    opened = _rest_openings(new, ref)

    def correspond() -> tuple:
        """The correspondence (seed 003 sections 3.1-3.2) and the new mesh with the fields pulled back."""
        lm_arr = np.stack([new.landmarks[n] for n in names])

        # seed 003 section 3.1: one cylinder per face, fitted near the landmarks, unrolled
        cyl_ref = fit_cylinder(ref.vertices[_region(ref.vertices, np.stack(list(ref_pts.values())), radius)])
        cyl_new = fit_cylinder(new.vertices[_region(new.vertices, lm_arr, radius)])
        chart_new = CylinderChart.facing(cyl_new, FORWARD)
        uv_ref, _ = CylinderChart.facing(cyl_ref, FORWARD).flatten(ref.vertices)
        uv_new, _, keep = flat_triangulation(chart_new, new.vertices, new.triangles)
        ref_ids = np.array([ref.landmarks[n] for n in names])
        lm_uv_new, _ = chart_new.flatten(lm_arr)

        # section 3.2: move the characteristic points, relax (eq 8), project back
        relax, rest_pos = _relax(uv_ref, ref.triangles, ref_ids, lm_uv_new, opt.area_stiffness)
        flat = relax.positions
        folded = int((np.sign(_signed_areas(flat, ref.triangles))
                      != np.sign(_signed_areas(rest_pos, ref.triangles))).sum())
        on_new, hit = project_back(chart_new, flat, new.vertices, new.triangles, uv_new, keep)
        errors = {n: float(np.linalg.norm(on_new[i] - new.landmarks[n])) for n, i in zip(names, ref_ids)}
        on_new[ref_ids] = lm_arr
        smap = SurfaceMap(ref.vertices, ref.triangles, on_new)

        # the rig: per-vertex fields pulled back through the chart, points carried forward
        tri, bary, _ = locate_2d(_probes(chart_new, new.vertices, new.triangles, new.cut, uv_new), flat, ref.triangles)
        # inside the mask's outer border, or less than about a triangle beyond it (the two meshes'
        # borders never match exactly; the reference decides there what is held)
        inside = in_polygon(uv_new, flat[outer_loop(flat, ref.triangles)]) | (bary.min(axis=1) > -0.75)
        mesh = _new_mesh(reference, smap, new, tri, bary, inside, landmarks.path, head.path)
        return (mesh, cyl_ref, cyl_new, chart_new, uv_new, keep, relax, folded, hit, errors, smap, inside)

    mesh, cyl_ref, cyl_new, chart_new, uv_new, keep, relax, folded, hit, errors, smap, inside = correspond()
    if opt.rest_lips:  # a mouth open at rest: its jaw closed by the hinge just carried, then all made again
        closed, shut = close_jaw(mesh)
        if shut:
            moved = np.asarray(closed.vertices, float) - new.vertices
            new.vertices = np.asarray(closed.vertices, float)
            new.landmarks = {n: p + moved[new.landmark_vertex[n]] for n, p in new.landmarks.items()}
            opened += shut
            mesh, cyl_ref, cyl_new, chart_new, uv_new, keep, relax, folded, hit, errors, smap, inside = correspond()
    if opt.seat_eyes:
        mesh, seated = seat_eyes(mesh)
        opened += seated
    if opt.rest_lips:
        mesh, closed = rest_lips(mesh, ref)
        opened += closed
    cavity = inside & hidden_under(chart_new, new.vertices, new.triangles, uv_new, keep, CAVITY_DEPTH * radius)
    if opt.seat_eyes and cavity.any():  # skin the seated lids uncover (a shut lid's margin) is not lining
        uv_seated, _, keep_seated = flat_triangulation(chart_new, mesh.vertices, new.triangles)
        cavity &= hidden_under(chart_new, mesh.vertices, new.triangles, uv_seated, keep_seated,
                               CAVITY_DEPTH * radius)
    if cavity.any():  # the head's own lining of the mouth, sockets, nostrils: drawn dark
        mesh.regions["cavity"] = cavity
    muscles = {ch: _carry(smap, parts, opt) for ch, parts in reference.muscles.items()}
    if opt.place_lower_lids:
        muscles, placed = place_lower_lids(reference, mesh, muscles)
        opened += placed
    support = lid_support(mesh) if opt.lid_support else None
    rig = FaceRig(mesh=mesh, muscles=muscles, wrinkles=_carry_wrinkles(reference, smap), name=name,
                  integrator=opt.integrator, presets=IMPORTED_PRESETS,
                  skin={} if support is None else {"support": support})
    notes = [] if refined is None else [refined]
    if opt.match_forces:
        rig.muscles, factors = match_forces(reference, rig)
        changed = {ch: k for ch, k in factors.items() if k > 1.25}
        if changed:
            listed = ", ".join(f"{ch} {k:.2f}" for ch, k in sorted(changed.items()))
            notes.append(f"{len(changed)} of {len(factors)} channels' force scaled (above x1.25; none is scaled down) "
                         f"to pull as hard in all as the reference's: {listed}")
    if support is not None:
        notes.append(f"{int((support < 1).sum())} lid vertices turned away from the front (folded into the "
                     "socket) have less of the skin's normal support")
    if new.split:
        what = "1 vertex" if new.split == 1 else f"{new.split} vertices"
        notes.append(f"{what} where the mesh's border touched itself near the face split in two (an opening's "
                     "border must be a simple loop); check the lips and lids there")
    for what in opened:
        notes.append(what)
    if not relax.converged:
        notes.append(f"the relaxation stopped before coming to rest (residual {relax.residual:.2g})")
    if folded:
        notes.append(f"{folded} triangles of the relaxed mask are folded: check the landmarks near them")
    if max(shape.values()) > 1.5:
        worst = max(shape, key=shape.get)  # type: ignore[arg-type]
        notes.append(f"{worst} is {shape[worst]:.1f} cm from where the reference face has it: check it")
    dense = dense_warning(len(mesh.vertices), len(ref.vertices))
    if dense:
        notes.append(dense)
    return Transfer(rig, sim, cyl_ref, cyl_new, relax, shape, errors, int((~hit).sum()), folded,
                    int((~inside).sum()), new.flipped, new.dropped, notes, dense)


def _refine(new: _Head, ref: FaceMesh, ref_pts: dict[str, FloatArray], lf: LandmarkFile, names: list[str],
            radius: float) -> str | None:
    """Split a coarse head's triangles (sim.face.transfer.refine: over `COARSE` x the reference's
    edges near the landmarks, until within `FINE` x); opening loops and cut slits follow. Landmarks the
    file gives as points go to their nearest point on the smoothed surface and its nearest vertex
    (one on the same opening when the coarse one was on an opening's rim; kept on a cut slit, whose
    sides coincide); those given as vertex indices follow their vertex. Returns the report's note,
    None if the head is not coarse."""
    width = float(np.linalg.norm(new.landmarks["eye_outer_l"] - new.landmarks["eye_outer_r"]))
    ref_width = float(np.linalg.norm(ref_pts["eye_outer_l"] - ref_pts["eye_outer_r"]))
    lm_arr = np.stack([new.landmarks[n] for n in names])
    scale = edge_scale(new.vertices, new.triangles, _region(new.vertices, lm_arr, radius), width)
    ref_scale = edge_scale(ref.vertices, ref.triangles,
                           _region(ref.vertices, np.stack([ref_pts[n] for n in names]), radius), ref_width)
    levels = levels_needed(scale, ref_scale)
    if levels == 0:
        return None
    before = len(new.vertices)
    cut_keys = [k for k, loop in new.openings.items() if any(loop is c for c in new.cut)]
    verts, tris, loops = new.vertices, new.triangles, dict(new.openings)
    for _ in range(levels):  # the face only: a head's back and neck are held and keep their mesh
        verts, tris, loops = subdivide(verts, tris, loops, _region(verts, lm_arr, radius))
    new.vertices, new.triangles, new.openings = verts, tris, loops
    new.cut = [loops[k] for k in cut_keys]
    on_loop = {int(v): k for k, loop in loops.items() for v in loop}
    tree = cKDTree(verts)
    given = np.stack([new.landmarks[n] for n in names])
    foot = closest_points(given, verts, tris)[0]  # the file's points on the smoothed surface
    for i, n in enumerate(names):
        if isinstance(lf.entries[n], (int, np.integer)):
            new.landmarks[n] = verts[new.landmark_vertex[n]].copy()  # named by index: it moved with the surface
            continue
        new.landmarks[n] = foot[i]
        key = on_loop.get(new.landmark_vertex[n])
        if key in cut_keys:  # a slit's two sides coincide: the landmark keeps its side
            continue
        if key is None:
            _, order = tree.query(foot[i], k=8)
            free = [int(j) for j in np.atleast_1d(order) if int(j) not in on_loop]
            if free:
                new.landmark_vertex[n] = free[0]
        else:
            ring = loops[key]
            new.landmark_vertex[n] = int(ring[np.linalg.norm(verts[ring] - foot[i], axis=1).argmin()])
    return (f"the head is coarse (its edges near the landmarks {scale / ref_scale:.1f} x the reference's, for "
            f"the eyes' width): its triangles were split {levels} time(s) for the simulation, "
            f"{before} -> {len(verts)} vertices")


def _gap_ratio(mesh: FaceMesh, upper: str, lower: str, a: str, b: str) -> float:
    """An opening's width at rest (between two landmarks) over its corner-to-corner length."""
    p = mesh.landmark
    return float(np.linalg.norm(p(upper) - p(lower)) / np.linalg.norm(p(a) - p(b)))


def _rest_openings(new: _Head, ref: FaceMesh) -> list[str]:
    """Lids shut in the file (declared as a lid line) are parted at rest by the reference's eye
    opening (sim.face.transfer.lids); landmarks follow. Returns notes for the report (with the corner
    landmarks that `_bring_in` put on a cut's ends). (Lips are
    left as modelled: brought to the reference's gap, a modelled head's mouth read worse.)"""
    notes = [f"{n} put on the end of its cut line, where the two sides meet ({d:.2f} cm from where it was given)"
             for n, d in new.corners.items()]
    before = new.vertices
    for side in "lr":
        loop = new.openings.get(f"eye_{side}")
        if loop is None or not any(loop is c for c in new.cut):
            continue
        ratio = _gap_ratio(ref, f"upper_lid_{side}", f"lower_lid_{side}", f"eye_outer_{side}", f"eye_inner_{side}")
        new.vertices = open_lids(new.vertices, loop, ratio, UP, new.triangles)
        notes.append(f"the lids of eye_{side} were shut; they were parted at rest by the reference's opening")
    if new.vertices is not before:  # landmarks given as points keep their place on the skin: they move as their vertex
        for n in new.landmarks:
            vid = new.landmark_vertex[n]
            new.landmarks[n] = new.landmarks[n] + new.vertices[vid] - before[vid]
    return notes


def _relax(uv_ref: FloatArray, triangles: IntArray, ref_ids: IntArray, targets: FloatArray,
           area_stiffness: float) -> tuple[Relaxation, FloatArray]:
    """Eq 8 on the unrolled reference mask with its characteristic points moved to `targets`.

    Rest shape: the mask placed on the new face by the best affine fit of the characteristic
    points (so the springs absorb only what an affine map cannot); start: that placement plus a
    thin-plate spline through the points' residuals. Returns the relaxation and the rest shape."""
    aff = _flat_fit(uv_ref[ref_ids], targets)
    rest_pos = np.column_stack([uv_ref, np.ones(len(uv_ref))]) @ aff
    tps = RBFInterpolator(uv_ref[ref_ids], targets - rest_pos[ref_ids], kernel="thin_plate_spline")
    start = rest_pos + tps(uv_ref)
    start[ref_ids] = targets
    fixed = np.zeros(len(uv_ref), bool)
    fixed[ref_ids] = True
    edges = unique_edges(triangles)
    rest = np.linalg.norm(rest_pos[edges[:, 1]] - rest_pos[edges[:, 0]], axis=1)
    relax = relax_mask(start, edges, rest, fixed, stiffness=rest.mean() / np.maximum(rest, 1e-12),
                       triangles=triangles, rest_area=0.5 * _signed_areas(rest_pos, triangles),
                       area_stiffness=area_stiffness)
    return relax, rest_pos


def _probes(chart: CylinderChart, verts: FloatArray, tris: IntArray, cut: list[IntArray],
            uv: FloatArray) -> FloatArray:
    """Where each new vertex looks up the reference's fields: its own flat position, except on a
    cut slit, where both lips (lids) sit at one place: those look a little into their own side
    (the mean of their triangles' centroids), so the lower lip gets the lower lip's jaw weight."""
    if not cut:
        return uv
    probes = uv.copy()
    centroids = verts[tris].mean(axis=1)
    for loop in cut:
        for v in loop:
            near = centroids[(tris == v).any(axis=1)].mean(axis=0)
            probes[v] = chart.flatten(near[None])[0][0]
    return probes


def _interp(values: FloatArray, tri: IntArray, bary: FloatArray, triangles: IntArray) -> FloatArray:
    w = np.clip(bary, 0.0, None)
    w = w / w.sum(axis=1, keepdims=True)
    v = values[triangles[tri]]
    return np.einsum("pk,pk...->p...", w, v)


def _new_mesh(reference: FaceRig, smap: SurfaceMap, new: _Head, tri: IntArray, bary: FloatArray,
              inside: np.ndarray, lm_path: str, mesh_path: str) -> FaceMesh:
    """The new FaceMesh: per-vertex fields pulled back from the reference through the relaxed flat
    correspondence (from the nearest reference triangle where a vertex falls in an opening, a gap
    or just past the border); vertices farther out than the reference mask's outer border are
    held (bound to the skull)."""
    ref = reference.mesh
    rt = ref.triangles
    verts, tris, lm_new = new.vertices, new.triangles, new.landmarks
    held = (_interp(ref.held.astype(float), tri, bary, rt) > 0.5) | ~inside
    jaw = np.where(inside, _interp(np.asarray(ref.jaw_weight, float), tri, bary, rt), 0.0)
    regions = {k: (_interp(m.astype(float), tri, bary, rt) > 0.5) & inside for k, m in ref.regions.items()}
    uv = None if ref.uv is None else _interp(np.asarray(ref.uv, float), tri, bary, rt)
    landmarks = dict(new.landmark_vertex)
    extra = [n for n in ref.landmarks if n not in landmarks]
    if extra:
        carried = smap.points(np.stack([ref.landmark(n) for n in extra]))
        _, near = cKDTree(verts).query(carried)
        landmarks.update({n: int(i) for n, i in zip(extra, near)})
    eyes = smap.points(np.asarray(ref.eye_centers, float))
    widths = [np.linalg.norm(lm_new[f"eye_outer_{s}"] - lm_new[f"eye_inner_{s}"])
              / np.linalg.norm(ref.landmark(f"eye_outer_{s}") - ref.landmark(f"eye_inner_{s}")) for s in "lr"]
    pivot = np.asarray(ref.jaw_pivot, float)
    axis = np.asarray(ref.jaw_axis, float)
    p0, p1 = smap.points(np.stack([pivot - axis, pivot + axis]))
    new_axis = (p1 - p0) / np.linalg.norm(p1 - p0)
    openings = find_openings(verts, tris, lm_new, new.openings, mesh_path, lm_path)
    return FaceMesh(
        vertices=verts, triangles=tris.astype(np.int32), landmarks=landmarks, held=held,
        jaw_weight=np.clip(jaw, 0.0, 1.0), jaw_pivot=smap.point(pivot), jaw_axis=new_axis,
        eye_centers=eyes, eye_radius=float(ref.eye_radius * np.mean(widths)),
        eye_loops=(openings["eye_l"], openings["eye_r"]), mouth_loop=openings["mouth"],
        regions=regions, uv=uv)


def _declared(lf: LandmarkFile, head: HeadMesh) -> dict[str, IntArray]:
    """Declared openings, from the file's vertex indices to the welded mesh's."""
    out: dict[str, IntArray] = {}
    for key, loop in lf.openings.items():
        if loop.min() < 0 or loop.max() >= len(head.file_to_vertex):
            raise TransferError(f"{lf.path}: opening {key!r} names a vertex outside {head.path}'s "
                                f"{len(head.file_to_vertex)} vertices")
        out[key] = head.file_to_vertex[loop]
    return out


def _carry_wrinkles(reference: FaceRig, smap: SurfaceMap) -> tuple:
    """The reference's wrinkle lines (seed 003's wrinkle mask) on the new face; lines of a type
    this module does not know (no frontal `points`) are dropped rather than guessed."""
    return tuple(carry_wrinkle(smap, w) for w in reference.wrinkles if hasattr(w, "points"))
