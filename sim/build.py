"""`compile_model(rig) -> FaceModel`: everything the integrator needs, as flat frozen arrays.

Skin parameters (`SkinParams`) are given per unit area so a face behaves the same at every mesh
resolution: node masses, damping, tethers and muscle forces all scale with the node's lumped area,
and spring stiffness comes from a membrane modulus (see `sim.springs.build_springs`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from sim.channels import CHANNEL_INDEX, CHANNEL_SPECS, HALVES, ChannelSpec
from sim.model import SKIN_FIELDS, FaceMesh, FaceRig
from sim.muscles import muscle_field
from sim.rowmath import norm3
from sim.springs import build_springs, vertex_areas
from sim.state import FaceState, rest_state

if TYPE_CHECKING:  # scipy.sparse is imported where a matrix is built: a cached face never needs it
    import scipy.sparse as sp

    from sim.csr import CsrArrays


@dataclass(frozen=True)
class SkinParams:
    """Material of the face, scale-free (per unit area), in cm, g, s.

    areal_density:  g/cm^2, skin plus subcutaneous tissue (~3 mm at ~1 g/cm^3).
    sheet_modulus:  dyn/cm, 2D Young's modulus of the skin membrane at low strain (k_l).
    high_ratio:     k_h / k_l, the stiffening beyond the strain threshold (seed 000 eq 3).
    strain_threshold: eps^c as a relative strain.
    bend_ratio:     bending spring stiffness relative to its edge spring.
    max_stiffness_ratio: cap on an edge spring's stiffness, in medians (sliver triangles).
    tether:         dyn/cm^3, seed 003 eq 9's feedback stiffness k per unit area (skin to skull).
    support:        dyn/cm^3, extra stiffness per unit area against motion along the rest normal only
                    (the fat and bone under the skin resist indentation more than sliding). Without
                    it a membrane with only spring bending is bistable under the muscles' in-plane
                    compression: the pulled skin buckles in or out depending on the transient.
    mass_damping:   1/s, c_i = mass_damping * m_i (seed 000 eq 23's velocity damping).
    viscosity:      s, axial spring damping per unit stiffness relative to the value that critically
                    damps the mesh's stiffest mode (1.0); dermis is viscoelastic and this lets the
                    explicit step run at its stability bound. Barely touches the slow expression modes.
    min_mass_fraction: mass scaling for the explicit step: a node's *inertial* mass is at least this
                    fraction of the median nodal mass. The default mesh is graded (elements at the
                    mouth corners and lid margins are 20x smaller than on the cheek) and omega ~ 1/edge,
                    so a handful of tiny nodes would set the step for the whole face; raising their
                    inertia does not change any static pose (gravity and tethers keep the true mass
                    and area).
    gravity:        whether m_i g acts (true mass); g in cm/s^2 along -Y.
    gravity_balanced: whether the rest pose is an equilibrium under gravity: each free vertex's
                    tether target is moved by the offset whose tether and support forces carry the
                    vertex's weight at its rest position (`gravity_offsets`), the way the tissue under
                    real skin is pre-stressed by it. Off, the face sags ~1 mm out of its rest shape.
    jaw_max_angle:  rad, jaw rotation at jaw = 1 (AU27).
    jaw_max_slide:  cm of a reference face (IPD 6.3 cm, scaled by the face's), the condyles' glide
                    forward and down the articular eminence at jaw = 1 (`jaw_slide_angle` rad below
                    the horizontal): a wide-open mouth is the hinge rotation plus this translation,
                    which keeps the chin from swinging back into the throat.
    lid_bending, lip_bending: stiffness of the bending term along the lid and the lip rows,
                    relative to the row's edge springs (`sim.margin_contact.margin_bending`; the
                    implicit integrator only, 0 turns it off): on fine meshes a pressed margin
                    otherwise buckles into a zig-zag. The lids' is the stiffer (their margins are
                    the tarsal plates); the lips' also resists the lip line's bending as the mouth
                    opens (AU27 at 3k vertices: 45.5 mm at 0, 45.1 at 1, 44.6 at 2).
    skin_bending:   the skin's own bending about its rest shape, relative to the median edge spring
                    (`sim.antifold.skin_bending`; the implicit integrator only, 0 turns it off): a
                    fine mesh's compressed skin otherwise buckles into mesh-scale ripples.
    forehead_bending: that bending over the forehead (from half a centimetre above the brows), in the skin's own: the
                    layer bound there (skin, connective tissue, frontalis, galea) is thicker than
                    skin alone (`sim.antifold.bound_layer`; the scanned head
                    `sim.antifold.FOREHEAD_BENDING`, 8). 1: as the rest of the skin (and left out
                    of the face's hash, so faces without it keep theirs).
    """

    areal_density: float = 0.3
    sheet_modulus: float = 6000.0
    high_ratio: float = 3.0
    strain_threshold: float = 0.15
    bend_ratio: float = 0.3
    max_stiffness_ratio: float = 3.0
    tether: float = 3000.0
    support: float = 9000.0
    mass_damping: float = 120.0
    viscosity: float = 1.0
    min_mass_fraction: float = 1.0
    gravity: bool = True
    g: float = 981.0
    gravity_balanced: bool = True
    jaw_max_angle: float = 0.55
    jaw_max_slide: float = 1.4
    jaw_slide_angle: float = 0.6
    lid_bending: float = 3.0
    lip_bending: float = 1.0
    skin_bending: float = 0.5
    forehead_bending: float = 1.0


@dataclass(frozen=True, eq=False)
class FaceModel:
    """The compiled face. Arrays are read-only. N vertices, M triangles, S springs, C channels.

    rig, mesh:           the source FaceRig and its FaceMesh.
    rest (N,3) cm; triangles (M,3) int32.
    spring_indices (S,2) int32: edge springs first (n_edge_springs of them), then bending springs.
    spring_rest_length (S,) cm; spring_k_low, spring_k_high (S,) dyn/cm; spring_damping (S,) dyn*s/cm
    (axial, along the spring); strain_threshold: relative strain eps^c.
    area (N,) cm^2 lumped; mass (N,) g inertial (after mass scaling); weight (N,) dyn, the true
    mass times g (zero with gravity off); damping (N,) g/s (c_i); rest_stiffness (N,) dyn/cm (eq 9 k);
    rest_normal (N,3) unit area-weighted vertex normals at rest; support_stiffness (N,) dyn/cm;
    eye_contact (K,) int: vertices that may touch an eyeball; eye_contact_eye (K,) int: which one
    (0 left, 1 right); eye_contact_radius (cm): they are kept at least this far from the eye centres
    (the lids slide over the eyeballs instead of passing through them).
    rest_offset (N,3) cm: added to every tether target (turned with the jaw like the target); the
    weight-carrying pre-stress of `gravity_offsets` (zero for held vertices, or with gravity off).
    held (N,) bool (pinned); jaw_weight (N,); jaw_pivot (3,); jaw_axis (3,); gravity (3,) cm/s^2.
    muscle_matrix: CSR (3N, C): column c = channel c's nodal force (dyn) at activation 1,
                   flattened xyz per vertex; zero columns for non-muscle channels (a scipy
                   csr_matrix when built, a sim.csr.CsrArrays of the same arrays from the cache).
    channels, channel_index: the channel specs (see sim.channels) and name -> column.
    params: the SkinParams; hash: hex identity of the rig + parameters (for recordings).
    """

    rig: FaceRig
    mesh: FaceMesh
    rest: np.ndarray
    triangles: np.ndarray
    spring_indices: np.ndarray
    n_edge_springs: int
    spring_rest_length: np.ndarray
    spring_k_low: np.ndarray
    spring_k_high: np.ndarray
    spring_damping: np.ndarray
    strain_threshold: float
    area: np.ndarray
    mass: np.ndarray
    weight: np.ndarray
    damping: np.ndarray
    rest_stiffness: np.ndarray
    rest_normal: np.ndarray
    support_stiffness: np.ndarray
    rest_offset: np.ndarray
    eye_contact: np.ndarray
    eye_contact_eye: np.ndarray
    eye_contact_radius: float
    held: np.ndarray
    jaw_weight: np.ndarray
    jaw_pivot: np.ndarray
    jaw_axis: np.ndarray
    gravity: np.ndarray
    muscle_matrix: sp.csr_matrix | CsrArrays
    params: SkinParams
    omega_max: float
    channels: tuple[ChannelSpec, ...] = CHANNEL_SPECS
    channel_index: dict[str, int] = field(default_factory=lambda: dict(CHANNEL_INDEX))
    hash: str = ""

    @property
    def n_vertices(self) -> int:
        return len(self.rest)

    def rest_state(self) -> FaceState:
        """A fresh state at rest."""
        return rest_state(self.rest)

    def control(self):  # type: ignore[no-untyped-def]
        """A fresh FaceControl at the channel defaults."""
        from sim.state import FaceControl

        return FaceControl(self)

    def landmark_index(self, name: str) -> int:
        return int(self.mesh.landmarks[name])


def omega_bound(
    rest: np.ndarray,
    springs: np.ndarray,
    k: np.ndarray,
    tether: np.ndarray,
    mass: np.ndarray,
    free: np.ndarray,
) -> float:
    """Upper bound (rad/s) on the highest natural frequency of the free nodes at rest, by block
    Gershgorin on M^-1/2 K M^-1/2: omega^2 <= max_i [lambda_max(K_ii) / m_i + sum_j k_ij / sqrt(m_i m_j)]
    with K_ii = sum_j k_ij u_ij u_ij^T + k_r,i I and j over free neighbours (held ones are fixed)."""
    i, j = springs[:, 0].astype(np.int64), springs[:, 1].astype(np.int64)
    d = rest[j] - rest[i]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    outer = k[:, None, None] * u[:, :, None] * u[:, None, :]
    kii = np.zeros((len(rest), 3, 3))
    np.add.at(kii, i, outer)
    np.add.at(kii, j, outer)
    kii += tether[:, None, None] * np.eye(3)
    diag = np.linalg.eigvalsh(kii)[:, -1] / mass
    coupling = k / np.sqrt(mass[i] * mass[j])
    off = np.zeros(len(rest))
    np.add.at(off, i, np.where(free[j], coupling, 0.0))
    np.add.at(off, j, np.where(free[i], coupling, 0.0))
    bound = np.where(free, diag + off, 0.0)
    return float(np.sqrt(bound.max()))


def stiffness_matrix(rest: np.ndarray, springs: np.ndarray, k: np.ndarray, tether: np.ndarray) -> sp.csr_matrix:
    """The skin's linear stiffness at rest, (3N, 3N) dyn/cm, xyz interleaved per vertex:
    sum over springs of k_s (e_i - e_j)(e_i - e_j)^T (x) u_s u_s^T, plus k_r,i I on the diagonal."""
    import scipy.sparse as sp

    n = len(rest)
    i, j = springs[:, 0].astype(np.int64), springs[:, 1].astype(np.int64)
    d = rest[j] - rest[i]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    blocks = k[:, None, None] * u[:, :, None] * u[:, None, :]  # (S,3,3)
    a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    rows, cols, vals = [], [], []
    for p, q, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
        rows.append((3 * p[:, None, None] + a).ravel())
        cols.append((3 * q[:, None, None] + b).ravel())
        vals.append((sign * blocks).ravel())
    rows.append(np.arange(3 * n))
    cols.append(np.arange(3 * n))
    vals.append(np.repeat(tether, 3))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))


def omega_exact(stiffness: sp.csr_matrix, mass: np.ndarray, free: np.ndarray) -> float:
    """Highest natural frequency (rad/s) of the free nodes at rest: sqrt of the largest eigenvalue of
    M^-1/2 K M^-1/2 restricted to free degrees of freedom (Lanczos, scipy eigsh)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import eigsh

    dof = np.repeat(free, 3)
    scale = 1.0 / np.sqrt(np.repeat(mass, 3)[dof])
    kf = stiffness[dof][:, dof]
    a = sp.diags(scale) @ kf @ sp.diags(scale)
    v0 = np.ones(a.shape[0])  # fixed start vector: the result is reproducible
    lam = eigsh(a, k=1, which="LA", tol=1e-6, v0=v0, return_eigenvectors=False)
    # to 7 significant digits (eigsh's tolerance is 1e-6): its last bits follow the BLAS kernel in
    # use, and the compiled face (its hash, every replay digest) must not
    return float(f"{np.sqrt(lam[0]):.7g}")


def _eye_contact(mesh: FaceMesh, rest: np.ndarray, held: np.ndarray) -> dict:
    """Free vertices within 1 cm outside an eyeball at rest, and a contact radius that the rest pose
    respects: the eyeball radius plus half a millimetre, or less if the lids lie closer at rest.
    Vertices inside the sphere at rest (a mesh not built around its eyeballs) are left out."""
    centres = np.asarray(mesh.eye_centers, dtype=np.float64)
    dist = np.linalg.norm(rest[:, None, :] - centres[None, :, :], axis=2)  # (N, 2)
    eye = np.argmin(dist, axis=1)
    gap = dist[np.arange(len(rest)), eye] - float(mesh.eye_radius)
    near = np.flatnonzero((gap >= 0.0) & (gap < 1.0) & ~held)  # a mesh without lids on the eyes
    clearance = min(0.05, 0.8 * float(gap[near].min())) if len(near) else 0.0  # may cross them
    return {
        "eye_contact": _frozen(near.astype(np.int64)),
        "eye_contact_eye": _frozen(eye[near].astype(np.int64)),
        "eye_contact_radius": float(mesh.eye_radius) + max(clearance, 0.0),
    }


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals (N,3), pointing out of the skin (CCW triangles)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    fn = np.cross(b - a, c - a)
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, triangles[:, k], fn)
    norm = np.linalg.norm(out, axis=1)
    return out / np.where(norm > 0, norm, 1.0)[:, None]


def gravity_offsets(weight: np.ndarray, tether: np.ndarray, support: np.ndarray, normal: np.ndarray,
                    held: np.ndarray) -> np.ndarray:
    """(N,3) cm: per free vertex the offset d of its tether target with (k_r I + k_n n n^T) d = -w,
    so that at the rest position the tether (seed 003 eq 9) and the normal support carry the vertex's
    weight w = m g exactly (springs are at rest length there, muscles off): the rest pose is an
    equilibrium. Closed form: (k_r I + k_n n n^T)^-1 = (I - k_n / (k_r + k_n) n n^T) / k_r."""
    along = np.sum(weight * normal, axis=1)
    d = -(weight - (support / (tether + support) * along)[:, None] * normal) / tether[:, None]
    d[np.asarray(held, dtype=bool)] = 0.0
    return d


#: A muscle part whose name ends so belongs to its whole channel only, not to the channel's sided
#: halves (`sim.channels.HALVES`): what the two sides make only together (the mentalis' bellies
#: pushing the lower lip out over the midline, `sim.face.scan.make_rig.mentalis_pout`).
BOTH_SIDES = "_both_sides"

#: The width of the sided halves' blend across the midline (`side_weight`), a share of the eyes'
#: distance: 3 mm on a face whose eyes are 6.2 cm apart.
SIDE_BLEND = 0.3 / 6.2


def side_weight(mesh: FaceMesh, rest: np.ndarray, side: str) -> np.ndarray:
    """(N,) the share of a paired muscle's field that is the face's `side` ("l" or "r") half:
    0.5 (1 + tanh(s / w)) of the signed distance s from the midline (the plane halfway between the
    eyes' centres, + towards the left eye), w = SIDE_BLEND times the eyes' distance. The two sides'
    shares sum to 1, so both halves at one value pull as the whole channel does."""
    ec = np.asarray(mesh.eye_centers, np.float64)
    axis = ec[0] - ec[1]
    dist = float(np.linalg.norm(axis))
    s = (np.asarray(rest, np.float64) - 0.5 * (ec[0] + ec[1])) @ (axis / dist)
    left = 0.5 * (1.0 + np.tanh(s / (SIDE_BLEND * dist)))
    return left if side == "l" else 1.0 - left


def _muscle_matrix(rig: FaceRig, rest: np.ndarray, area: np.ndarray,
                   normal: np.ndarray | None = None,
                   springs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                   tether: np.ndarray | None = None) -> sp.csr_matrix:
    """(3N, C) each channel's force field at full value: its muscle's pull (times the fitted
    insertion gain), plus its active strain's force (`sim.active_strain`; `springs`: indices, rest
    lengths, k_low of the skin's springs) where the rig has one, plus the tether's pull towards its
    moved anchors (`FaceRig.anchor`, `tether` (N,) dyn/cm: k_r d, exact since the tether is linear).
    A sided half (`sim.channels.HALVES`) pulls as its whole channel weighted by `side_weight`, but
    for the whole's parts named with BOTH_SIDES, with anchors of its own."""
    import scipy.sparse as sp

    n = len(rest)
    if normal is None:
        normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))

    pulls: dict[tuple[str, bool], np.ndarray | None] = {}  # a whole channel's pull, made once for it and its halves

    def pull(name: str, half: bool = False) -> np.ndarray | None:
        if (name, half) not in pulls:
            pulls[name, half] = _pull(name, half)
        return pulls[name, half]

    def _pull(name: str, half: bool) -> np.ndarray | None:
        parts = rig.muscles.get(name, ())
        if half:  # a part both sides make together is the whole channel's only (BOTH_SIDES)
            parts = tuple(m for m in parts if not m.name.endswith(BOTH_SIDES))
        if not parts:
            return None
        f = muscle_field(parts, rest, area, normal)
        gain = rig.insertion.get(name)
        if gain is not None:  # the fitted insertion density (sim.model.FaceRig.insertion)
            f = f * np.asarray(gain, np.float64)[:, None]
        strain = rig.strain.get(name)
        if strain is not None and springs is not None:  # the tissue's active strain (FaceRig.strain)
            from sim.active_strain import strain_force

            f = f + strain_force(rest, springs[0], springs[1], springs[2], np.asarray(strain, np.float64))
        return f

    cols = []
    for spec in CHANNEL_SPECS:
        f = None
        if spec.kind == "muscle":
            if spec.name in HALVES:
                whole, side = HALVES[spec.name]
                f = pull(whole, half=True)
                if f is not None:
                    f = f * side_weight(rig.mesh, rest, side)[:, None]
            else:
                f = pull(spec.name)
        if f is not None:
            anchor = rig.anchor.get(spec.name)
            if anchor is not None and tether is not None:  # the deep layer carrying the tether's anchors
                f = f + np.asarray(tether, np.float64)[:, None] * np.asarray(anchor, np.float64)
            cols.append(sp.csc_matrix(f.reshape(3 * n, 1)))
        else:
            cols.append(sp.csc_matrix((3 * n, 1)))
    m = sp.hstack(cols).tocsr()
    m.eliminate_zeros()
    return m


def _rig_digest(rig: FaceRig, params: SkinParams) -> str:
    h = hashlib.sha256()
    mesh = rig.mesh
    for arr in (mesh.vertices, mesh.triangles, mesh.held, mesh.jaw_weight, mesh.jaw_pivot, mesh.jaw_axis):
        a = np.ascontiguousarray(arr)
        h.update(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    for name in sorted(rig.muscles):
        for m in rig.muscles[name]:
            h.update(type(m).__name__.encode() + name.encode())
            for key, val in sorted(vars(m).items()):
                if key == "protrude" and val == 0.0:  # a ring without it (every face's but the pucker's): hash unchanged
                    continue
                raw = val.encode() if isinstance(val, str) else np.asarray(val, np.float64).tobytes()
                h.update(key.encode() + raw)
    for name in sorted(rig.insertion):  # none on a face without fitted insertions: its hash is unchanged
        h.update(b"insertion" + name.encode() + np.ascontiguousarray(rig.insertion[name], np.float64).tobytes())
    for name in sorted(rig.skin):  # none on a face with uniform skin: its hash is unchanged
        h.update(b"skin" + name.encode() + np.ascontiguousarray(rig.skin[name], np.float64).tobytes())
    for name in sorted(rig.strain):  # none on a face without active strain: its hash is unchanged
        h.update(b"strain" + name.encode() + np.ascontiguousarray(rig.strain[name], np.float64).tobytes())
    for name in sorted(rig.anchor):  # none on a face whose anchors stay: its hash is unchanged
        h.update(b"anchor" + name.encode() + np.ascontiguousarray(rig.anchor[name], np.float64).tobytes())
    for name in sorted(rig.gaze):  # none on a face without the tissue carried by the eyes: its hash is unchanged
        h.update(b"gaze" + name.encode() + np.ascontiguousarray(rig.gaze[name], np.float64).tobytes())
    for name in sorted(rig.tissue):  # none on a face without named structures: its hash is unchanged
        h.update(b"tissue" + name.encode() + np.ascontiguousarray(rig.tissue[name], np.float64).tobytes())
    if rig.integrator != "auto":  # a face that asks for its integrator replays on it
        h.update(b"integrator" + rig.integrator.encode())
    for line in rig.wrinkles:  # WrinkleLine.to_dict() is plain JSON
        h.update(json.dumps(line.to_dict(), sort_keys=True).encode())
    p = asdict(params)
    if p["forehead_bending"] == 1.0:  # a face without the forehead's bound layer keeps its hash
        del p["forehead_bending"]
    h.update(json.dumps(p, sort_keys=True).encode())
    return h.hexdigest()[:16]


def _frozen(a: np.ndarray, dtype: type | None = None) -> np.ndarray:
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def compile_model(rig: FaceRig, params: SkinParams | None = None) -> FaceModel:
    """Springs, masses, tethers and muscle fields from the rig's rest geometry, frozen."""
    p = params or SkinParams()
    mesh = rig.mesh
    rest = np.asarray(mesh.vertices, dtype=np.float64)
    tris = np.asarray(mesh.triangles, dtype=np.int32)
    springs, rest_len, k_low, n_edge = build_springs(rest, tris, p.sheet_modulus, p.bend_ratio,
                                                    p.max_stiffness_ratio)
    skin = {name: np.asarray(rig.skin.get(name, np.ones(len(rest))), np.float64) for name in SKIN_FIELDS}
    for key in sorted(rig.tissue):  # named structures on top of the fitted fields (FaceRig.tissue)
        name = key.split("_", 1)[0]
        skin[name] = skin[name] * np.asarray(rig.tissue[key], np.float64)
    if "modulus" in rig.skin or any(k.startswith("modulus_") for k in rig.tissue):  # a spring's material is the mean of its two ends' (FaceRig.skin)
        k_low = k_low * 0.5 * (skin["modulus"][springs[:, 0]] + skin["modulus"][springs[:, 1]])
    area = vertex_areas(rest, tris)
    area = np.maximum(area, 1e-6)
    true_mass = p.areal_density * area
    held = np.asarray(mesh.held, dtype=bool)
    floor = p.min_mass_fraction * float(np.median(true_mass[~held] if (~held).any() else true_mass))
    mass = np.maximum(true_mass, floor)
    gravity = np.array([0.0, -p.g if p.gravity else 0.0, 0.0])
    tether = p.tether * area * skin["tether"]
    k_high = p.high_ratio * k_low
    support = p.support * area * skin["support"]
    bound = tether + support  # isotropic stand-in for k_r I + k_n n n^T: an upper bound
    omega = omega_exact(stiffness_matrix(rest, springs, k_high, bound), mass, ~held)
    omega_low = omega_exact(stiffness_matrix(rest, springs, k_low, bound), mass, ~held)
    spring_damping = p.viscosity * (2.0 / omega_low) * k_low
    weight = true_mass[:, None] * gravity[None, :]
    normal = vertex_normals(rest, tris)
    offset = (gravity_offsets(weight, tether, support, normal, held) if p.gravity_balanced
              else np.zeros_like(rest))
    model = FaceModel(
        rig=rig,
        mesh=mesh,
        rest=_frozen(rest),
        triangles=_frozen(tris),
        spring_indices=_frozen(springs),
        n_edge_springs=n_edge,
        spring_rest_length=_frozen(rest_len),
        spring_k_low=_frozen(k_low),
        spring_k_high=_frozen(k_high),
        spring_damping=_frozen(spring_damping),
        strain_threshold=p.strain_threshold,
        area=_frozen(area),
        mass=_frozen(mass),
        weight=_frozen(weight),
        damping=_frozen(p.mass_damping * mass),
        rest_stiffness=_frozen(tether),
        rest_normal=_frozen(normal),
        rest_offset=_frozen(offset),
        **_eye_contact(mesh, rest, held),
        support_stiffness=_frozen(support),
        held=_frozen(held),
        jaw_weight=_frozen(np.clip(mesh.jaw_weight, 0.0, 1.0), np.float64),
        jaw_pivot=_frozen(mesh.jaw_pivot, np.float64),
        jaw_axis=_frozen(np.asarray(mesh.jaw_axis) / norm3(mesh.jaw_axis), np.float64),
        gravity=_frozen(gravity),
        muscle_matrix=_muscle_matrix(rig, rest, area, normal, (springs, rest_len, k_low), tether),
        params=p,
        omega_max=omega,
        hash=_rig_digest(rig, p),
    )
    from sim.integrator import warm_up

    warm_up()
    return model
