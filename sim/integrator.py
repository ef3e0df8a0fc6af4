"""The integrator: seed 000 eq 23 with seed 003 eq 9's feedback force, advanced by explicit RK2.

Per node i (free, not held):
    m_i a_i = Q_i (springs, eqs 1-5) + axial spring damping - c_i v_i + k_r,i (target_i - x_i)
              + k_n,i n_i n_i.(target_i - x_i) (normal support, see SkinParams.support)
              + sum_c a_c F_c,i (muscles) + m_i g
and after every substep the closed lids and the lips are kept from passing each other
(`sim.margin_contact`; the implicit integrator solves that contact within its step) and the
vertices near the eyeballs outside them (`_eye_contact`).
RK2 reading chosen: the explicit *midpoint* method (Numerical Recipes' "second-order Runge-Kutta",
the paper's ref [16]): k1 = f(y); k2 = f(y + h/2 k1); y += h k2.

Jaw: `jaw` rotates the rest target of each vertex about the jaw hinge by jaw * jaw_max_angle, blended
by the vertex's jaw_weight (target = rest + w (R rest - rest)); the eq 9 tether then carries the skin
along, and held vertices (pinned) are placed on their target each frame, so a held chin edge follows
the jaw rigidly while held scalp and ear edges stay put.

Method: explicit RK2 is the paper's method and the default; `method="auto"` switches to the
linearly implicit integrator of `sim.implicit` only when RK2's work per frame (substeps x springs)
exceeds RK2_WORK_LIMIT, i.e. for the 3k and 12k faces (see benchmarks/sim_step.py).

Substeps: the step h is the largest h for which the RK2 amplification factor of every linear mode
(natural frequency up to `model.omega_max`, the largest eigenfrequency of the skin at rest computed
by compile_model, with the model's mass and spring damping) stays <= 1, times SAFETY;
substeps = ceil(frame_dt / h). See `stable_step` and docs/simulation.md.

The whole frame runs in one compiled (numba, serial) kernel: no threads, fixed summation order, so
the same inputs give bit-identical positions (on one machine and build).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numba
import numpy as np

from sim.build import FaceModel
from sim.channels import CHANNEL_INDEX
from sim.gaze_lids import N_BASIS, add_tissue_forces, basis_coefficients, gaze_forces, lid_couplings, tissue_fields
from sim.margin_contact import margin_contact, margin_pairs
from sim.state import FaceControl, FaceState
from sim.numba_start import prepare_blas_check
from sim.rowmath import norm3
from sim.wrinkles import aging

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

SAFETY = 0.9  # fraction of the linear stability limit used as the step (covers geometric stiffness)
BLOWUP_DISPLACEMENT = 6.0  # cm (x face scale): farther from its target than this is a blow-up
SETTLE_SPEED = 0.02  # cm/s: the face counts as settled when no vertex moves faster
RK2_WORK_LIMIT = 200_000  # spring evaluations per frame (substeps x springs, two per RK2 substep
# each) above which method="auto" picks the implicit integrator: ~3 ms of one core here


# numba options of every kernel: no fastmath (bit-identical results on any machine with IEEE
# doubles); error_model="numpy" lets a division by zero give inf instead of raising, which removes
# a branch from the inner loops and lets LLVM vectorize the spring math (sqrt and division are
# exactly rounded in SIMD too, so the results do not change).
KERNEL = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")


@numba.njit(**KERNEL)
def _spring_forces(xf, vf, si3, sj3, rest_len, k_low, k_high, k_damp, thr, dx, dy, dz, gx, gy, gz, fx, fy, fz):  # type: ignore[no-untyped-def]
    """Force on the first node of every spring (eqs 1-5 on relative strain, two slopes meeting at
    the knee thr * rest length, plus axial damping), into fx, fy, fz. xf, vf are the flat (3N)
    positions and velocities, si3/sj3 the springs' node indices times 3. Three passes: gather the
    edge vectors, the per-spring math (vectorized: no indexing), later a scatter (_node_forces)."""
    for s in range(si3.shape[0]):
        i = si3[s]
        j = sj3[s]
        dx[s] = xf[j] - xf[i]
        dy[s] = xf[j + 1] - xf[i + 1]
        dz[s] = xf[j + 2] - xf[i + 2]
        gx[s] = vf[j] - vf[i]
        gy[s] = vf[j + 1] - vf[i + 1]
        gz[s] = vf[j + 2] - vf[i + 2]
    for s in range(si3.shape[0]):
        r = math.sqrt(dx[s] * dx[s] + dy[s] * dy[s] + dz[s] * dz[s])
        inv = 1.0 / r
        ux = dx[s] * inv
        uy = dy[s] * inv
        uz = dz[s] * inv
        stretch = r - rest_len[s]
        knee = thr * rest_len[s]
        soft = k_low[s] * stretch
        stiff = k_low[s] * knee + k_high[s] * (stretch - knee)
        f = soft if stretch <= knee else stiff
        f += k_damp[s] * (gx[s] * ux + gy[s] * uy + gz[s] * uz)
        fx[s] = f * ux
        fy[s] = f * uy
        fz[s] = f * uz


@numba.njit(**KERNEL)
def _node_forces(x, v, si3, sj3, fx, fy, fz, ext, kr, c, nrm, kn, out):  # type: ignore[no-untyped-def]
    """out = the constant forces, minus the tether, damping and normal support terms at (x, v),
    plus the springs' forces (fx, fy, fz) scattered to both ends in spring order."""
    n = x.shape[0]
    for i in range(n):
        nx = nrm[i, 0] * x[i, 0] + nrm[i, 1] * x[i, 1] + nrm[i, 2] * x[i, 2]
        for d in range(3):
            out[i, d] = ext[i, d] - kr[i] * x[i, d] - c[i] * v[i, d] - kn[i] * nx * nrm[i, d]
    of = out.reshape(3 * n)
    for s in range(si3.shape[0]):
        i = si3[s]
        j = sj3[s]
        of[i] += fx[s]
        of[i + 1] += fy[s]
        of[i + 2] += fz[s]
        of[j] -= fx[s]
        of[j + 1] -= fy[s]
        of[j + 2] -= fz[s]


@numba.njit(**KERNEL)
def _constant_forces(indptr, indices, data, values, is_muscle, weight, kr, target, kn, nrm, out):  # type: ignore[no-untyped-def]
    """The forces constant over a frame, (N,3) dyn, into out: per node
    muscles (seed 000 eqs 9, 14, 18: the CSR (3N, C) muscle matrix times the muscle channels'
    activations, other channels counted as 0) + gravity m_i g (`weight`) + the constant part
    k_r,i target_i of seed 003 eq 9's F_r = k_r (target - x) + the constant part k_n,i n_i (n_i .
    target_i) of the normal support F_n = k_n n n.(target - x); the -k_r x and -k_n n (n . x)
    parts are evaluated per substep (_node_forces)."""
    n = out.shape[0]
    for i in range(n):
        support = kn[i] * (nrm[i, 0] * target[i, 0] + nrm[i, 1] * target[i, 1] + nrm[i, 2] * target[i, 2])
        for d in range(3):
            row = 3 * i + d
            acc = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                c = indices[k]
                if is_muscle[c]:
                    acc += data[k] * values[c]
            out[i, d] = acc + weight[i, d] + kr[i] * target[i, d] + support * nrm[i, d]


@numba.njit(inline="always")
def row_deviation(x, i, target, worst):  # type: ignore[no-untyped-def]
    """max(worst, |x[i] - target[i]|) over row i's coordinates, or -1 if one of x[i] is not finite
    (the guard's measure, one row: `_max_deviation`, `_held_deviation`, sim.implicit's free rows)."""
    for d in range(3):
        if not math.isfinite(x[i, d]):
            return -1.0
        dev = abs(x[i, d] - target[i, d])
        if dev > worst:
            worst = dev
    return worst


@numba.njit(**KERNEL)
def _max_deviation(x, target):  # type: ignore[no-untyped-def]
    """max |x - target| over all coordinates, or -1 if any coordinate of x is not finite."""
    worst = 0.0
    for i in range(x.shape[0]):
        worst = row_deviation(x, i, target, worst)
        if worst < 0.0:
            break
    return worst


@numba.njit(**KERNEL)
def _held_deviation(x, held, target, worst):  # type: ignore[no-untyped-def]
    """`_max_deviation` given `worst`, the free nodes' (sim.implicit._free_deviation, -1: not finite),
    completed over the held ones: the same answer as over all rows when they are the two parts."""
    for k in range(held.shape[0]):
        if worst < 0.0:
            break
        worst = row_deviation(x, held[k], target, worst)
    return worst


@numba.njit(**KERNEL)
def _hold(x, v, held, target):  # type: ignore[no-untyped-def]
    """The held nodes on their targets, at rest (x[held] = target[held], v[held] = 0, without
    numpy's gathered copy)."""
    for k in range(held.shape[0]):
        i = held[k]
        for d in range(3):
            x[i, d] = target[i, d]
            v[i, d] = 0.0


@numba.njit(**KERNEL)
def _save_hold(x, v, held, target, saved):  # type: ignore[no-untyped-def]
    """saved = x (the step's start, for the guard's restore), then `_hold`: one call where two ran
    back to back (numpy's copy and the kernel), the same values."""
    n = x.shape[0]
    for i in range(n):
        for d in range(3):
            saved[i, d] = x[i, d]
    _hold(x, v, held, target)


@numba.njit(**KERNEL)
def _eye_contact(x, v, idx, eye, centres, radius):  # type: ignore[no-untyped-def]
    """Keeps the contact vertices outside the eyeball spheres: a vertex inside is put back on the
    sphere and loses the inward part of its velocity (the eyeball is rigid and frictionless)."""
    for k in range(idx.shape[0]):
        i = idx[k]
        e = eye[k]
        dx = x[i, 0] - centres[e, 0]
        dy = x[i, 1] - centres[e, 1]
        dz = x[i, 2] - centres[e, 2]
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        if r < radius and r > 0.0:
            nx = dx / r
            ny = dy / r
            nz = dz / r
            x[i, 0] = centres[e, 0] + nx * radius
            x[i, 1] = centres[e, 1] + ny * radius
            x[i, 2] = centres[e, 2] + nz * radius
            vn = v[i, 0] * nx + v[i, 1] * ny + v[i, 2] * nz
            if vn < 0.0:
                v[i, 0] -= vn * nx
                v[i, 1] -= vn * ny
                v[i, 2] -= vn * nz


@numba.njit(**KERNEL)
def _rk2_frame(x, v, n_sub, h, si3, sj3, rest_len, k_low, k_high, k_damp, thr, ext, kr, c, nrm, kn, inv_mass,
               force, xm, vm, work, eye_idx, eye_of, centres, radius, lip_idx, lip_w, lip_sg):  # type: ignore[no-untyped-def]
    """n_sub explicit-midpoint substeps of size h, in place on x, v, each followed by the lid and
    lip contact (sim.margin_contact) and the eyeball contact (last, so no vertex is left inside an
    eyeball). inv_mass is 1/m for free nodes and 0 for held ones; force (N,3) and work (9,S) are
    scratch."""
    n = x.shape[0]
    half = 0.5 * h
    xf = x.reshape(3 * n)
    vf = v.reshape(3 * n)
    xmf = xm.reshape(3 * n)
    vmf = vm.reshape(3 * n)
    dx, dy, dz, gx, gy, gz, fx, fy, fz = work[0], work[1], work[2], work[3], work[4], work[5], work[6], work[7], work[8]
    for _ in range(n_sub):
        _spring_forces(xf, vf, si3, sj3, rest_len, k_low, k_high, k_damp, thr, dx, dy, dz, gx, gy, gz, fx, fy, fz)
        _node_forces(x, v, si3, sj3, fx, fy, fz, ext, kr, c, nrm, kn, force)
        for i in range(n):
            w = inv_mass[i]
            for d in range(3):
                xm[i, d] = x[i, d] + half * v[i, d]
                vm[i, d] = v[i, d] + half * (force[i, d] * w)
        _spring_forces(xmf, vmf, si3, sj3, rest_len, k_low, k_high, k_damp, thr, dx, dy, dz, gx, gy, gz, fx, fy, fz)
        _node_forces(xm, vm, si3, sj3, fx, fy, fz, ext, kr, c, nrm, kn, force)
        for i in range(n):
            w = inv_mass[i]
            for d in range(3):
                x[i, d] += h * vm[i, d]
                v[i, d] += h * (force[i, d] * w)
        margin_contact(x, v, lip_idx, lip_w, lip_sg, inv_mass)
        _eye_contact(x, v, eye_idx, eye_of, centres, radius)


def warm_up(implicit: bool = True) -> None:
    """Compile (or load from numba's on-disk cache) the kernels of both integrators (RK2 only with
    implicit=False) on a two-node system, so the first live frame does not stall. Called by
    compile_model."""
    if implicit:
        from sim.implicit import warm_up as warm_up_implicit

        warm_up_implicit()
    x1 = np.zeros((1, 3))
    frozen = np.zeros((1, 3))  # the model's weight is read-only: numba types it apart from a writable array
    frozen.setflags(write=False)
    _constant_forces(np.zeros(4, dtype=np.int32), np.zeros(0, dtype=np.int32), np.zeros(0), np.zeros(1),
                     np.ones(1, dtype=np.bool_), frozen, np.ones(1), x1, np.ones(1), x1, np.zeros((1, 3)))
    _fixed_forces(frozen, np.ones(1), x1, np.ones(1), x1, np.zeros((1, 3)))
    by_coordinate, turned, tmp = np.zeros((3, 1)), np.zeros((1, 3)), np.zeros((10, 1))
    for rows in (np.zeros((0, 3)), np.zeros((1, 3))):  # (the rest shape turned or not)
        _jaw_pose(by_coordinate, by_coordinate, np.ones((3, 1)), np.zeros(3), np.ones(1), np.eye(3), np.zeros(3),
                  turned, rows, np.zeros((1, 3)), tmp, frozen, np.ones(1), np.ones(1), rows)
    _place(np.zeros((1, 3)), np.array([0], dtype=np.int64), np.zeros((1, 3)))
    _open_pose(np.array([1.0, 0.0, 0.0]), 0.1, 0.01, 0.2, np.zeros(3), np.zeros((3, 3)), np.zeros(3), by_coordinate,
               by_coordinate, np.ones((3, 1)), np.zeros(3), np.ones(1), turned, np.zeros((0, 3)), np.zeros((1, 3)), tmp,
               frozen, np.ones(1), np.ones(1), np.zeros((1, 3)), np.zeros((1, 3)), np.array([0], dtype=np.int64))
    _grid_pose(np.array([1.0, 0.0, 0.0]), 0.1, 0.01, 0.2, np.zeros(3), np.zeros((3, 3)), np.zeros(3),
               np.zeros((3, 2, 1, 3), dtype=np.float32), frozen, np.ones(1), np.ones(1), turned, np.zeros((1, 3)),
               np.zeros((1, 3)), np.zeros((1, 3)), np.array([0], dtype=np.int64))
    _held_deviation(np.zeros((1, 3)), np.array([0], dtype=np.int64), np.zeros((1, 3)), 0.0)
    _active(np.ones(1), np.ones(1, dtype=np.bool_), np.zeros(1, dtype=np.int64), np.zeros(1))
    _max_deviation(x1, x1)
    _hold(np.zeros((1, 3)), np.zeros((1, 3)), np.array([0], dtype=np.int64), np.zeros((1, 3)))
    _save_hold(np.zeros((1, 3)), np.zeros((1, 3)), np.array([0], dtype=np.int64), np.zeros((1, 3)), np.zeros((1, 3)))
    _eye_contact(np.zeros((1, 3)), np.zeros((1, 3)), np.array([0], dtype=np.int64),
                 np.array([0], dtype=np.int64), np.array([[0.0, 0.0, 1.0]]), 0.5)
    x = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]])
    v = np.zeros_like(x)
    one = np.ones(1)
    ones2 = np.ones(2)
    _rk2_frame(x, v, 1, 1e-3, np.array([0], dtype=np.uint32), np.array([3], dtype=np.uint32), one, one, one,
               one, 0.1, np.zeros_like(x), ones2, ones2, np.zeros_like(x), ones2, ones2, np.zeros_like(x),
               np.zeros_like(x), np.zeros_like(x), np.zeros((9, 1)), np.array([1], dtype=np.int64),
               np.array([0], dtype=np.int64), np.array([[0.0, 0.0, 5.0]]), 1.0,
               np.array([[0, 1, 1]], dtype=np.int64), np.zeros(1), np.array([[1.0, 0.0, 1.0, 1.0]]))
    margin_contact(x, v, np.array([[0, 1, 1]], dtype=np.int64), np.zeros(1), np.array([[1.0, 0.0, 1.0, 1.0]]), ones2)


def kernels_cached() -> bool:
    """Whether numba's on-disk cache holds this version's RK2 and wrinkle kernels (False on the
    first start after an install or update, when preparing a face compiles for seconds). Reads
    numba's cache index (an internal of numba: any surprise answers False)."""
    try:
        from sim.wrinkles.kernels import frame_displacement

        return all(bool(k._cache._cache_file._load_index()) for k in (_rk2_frame, frame_displacement))
    except Exception:  # noqa: BLE001 - a changed numba: assume a cold cache
        return False


def rk2_amplification(z: np.ndarray) -> np.ndarray:
    """|R(z)| of any two-stage second-order explicit Runge-Kutta method on y' = lambda y, z = h lambda."""
    return np.abs(1.0 + z + 0.5 * z * z)


def stable_step(omega_max: float, mass_rate: float, visc: float, high_ratio: float) -> float:
    """Largest h (s) for which RK2 damps every mode of the linearised skin.

    A mode of the soft springs with omega^2 = mu has damping rate c/m = mass_rate + visc * mu (mass
    damping plus axial spring damping, which scales with the soft stiffness); past the strain
    threshold the same mode stiffens to high_ratio * mu with unchanged damping. omega_max bounds the
    stiff regime. We scan mu over (0, omega_max^2 / high_ratio] in both regimes and bisect h."""
    mu = np.linspace(0.0, omega_max**2 / high_ratio, 2001)[1:]
    lambdas = []
    for stiff in (mu, high_ratio * mu):
        b = mass_rate + visc * mu
        disc = np.sqrt((0.25 * b * b - stiff).astype(np.complex128))
        lambdas.append(-0.5 * b + disc)
        lambdas.append(-0.5 * b - disc)
    lam = np.concatenate(lambdas)
    lo, hi = 0.0, 4.0 / omega_max
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if np.all(rk2_amplification(mid * lam) <= 1.0 + 1e-12):
            lo = mid
        else:
            hi = mid
    return lo


#: The mandible's thrust (AU29) at jaw_forward = 1, cm of a reference face: the condyles glide
#: forward and down the articular eminences. Read off the ICT FaceKit's scanned jawForward (the lower
#: teeth's rigid motion: 8.9 mm forward, 1.7 mm down, no turn; adults protrude 7-11 mm).
JAW_THRUST, JAW_THRUST_DROP = 0.89, 0.17
#: Its sideways move (AU30) at jaw_sideways = +-1: a small turn about the vertical through the
#: hinge's midpoint and a lateral shift of the whole mandible (the Bennett movement), read off the
#: scanned jawLeft / jawRight (the lower teeth: 1.9 degrees, 6.4 mm sideways, 0.6 mm down; adult
#: lateral excursion 8-12 mm at the incisors).
JAW_YAW = math.radians(1.9)
JAW_SHIFT, JAW_SHIFT_DROP = 0.64, 0.06


def jaw_motion(model: FaceModel, jaw: float, forward: float = 0.0,
               sideways: float = 0.0, slide_one: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3,3), translation (3,) cm) of the mandible about `model.jaw_pivot` for a jaw
    opened by `jaw` (the hinge turn and the condyles' slide, `jaw_slide`), thrust forward by
    `forward` (0..1, AU29) and moved towards the face's left by `sideways` (-1..1, AU30).
    slide_one: `jaw_slide(model)` made before (it depends on the face alone)."""
    rot = jaw_rotation(model.jaw_axis, jaw * model.params.jaw_max_angle) if jaw else np.eye(3)
    slide = jaw * (jaw_slide(model) if slide_one is None else slide_one)
    if forward or sideways:
        s = _face_scale(model)
        axis = np.asarray(model.jaw_axis, dtype=np.float64)
        ahead = np.cross(axis, [0.0, 1.0, 0.0])
        ahead /= max(norm3(ahead), 1e-9)
        left = np.cross([0.0, 1.0, 0.0], ahead)  # +X on the default face
        rot = jaw_rotation(np.array([0.0, 1.0, 0.0]), sideways * JAW_YAW) @ rot
        down = np.array([0.0, -1.0, 0.0])
        slide = slide + s * (forward * (JAW_THRUST * ahead + JAW_THRUST_DROP * down)
                             + sideways * JAW_SHIFT * left + abs(sideways) * JAW_SHIFT_DROP * down)
    return rot, slide


@numba.njit(**KERNEL)
def _fixed_forces(weight, kr, target, kn, nrm, out):  # type: ignore[no-untyped-def]
    """`_constant_forces` with no muscle (the implicit step's, whose muscles enter as responses),
    each value by the same operations (the same bits) without the muscle matrix's empty rows:
    40 -> 15 us on the scanned head, remade at each new jaw pose."""
    for i in range(out.shape[0]):
        support = kn[i] * (nrm[i, 0] * target[i, 0] + nrm[i, 1] * target[i, 1] + nrm[i, 2] * target[i, 2])
        for d in range(3):
            acc = 0.0
            out[i, d] = acc + weight[i, d] + kr[i] * target[i, d] + support * nrm[i, d]


@numba.njit(inline="always")
def _fixed_row(i, g0, g1, g2, m0, m1, m2, w3, kr, kn, fixed):  # type: ignore[no-untyped-def]
    """Row i of `_fixed_forces`: the tether's pull to the target g and the support's along the unit
    normal m, beside the constant force w3 (the same sums in the same order wherever it is made)."""
    support = kn[i] * (m0 * g0 + m1 * g1 + m2 * g2)
    acc = 0.0
    q = kr[i]
    fixed[i, 0] = acc + w3[i, 0] + q * g0 + support * m0
    fixed[i, 1] = acc + w3[i, 1] + q * g1 + support * m1
    fixed[i, 2] = acc + w3[i, 2] + q * g2 + support * m2


@numba.njit(**KERNEL)
def _jaw_pose(rest, offset, normal3, pivot, weight, rot, slide, target, shape, normal, tmp, w3, kr, kn, fixed):  # type: ignore[no-untyped-def]
    """A new jaw pose's constants in one call: eq 9's target (and the rest shape when `shape` has
    rows), the support normals and, when `fixed` has rows, the implicit step's constant forces
    without muscles (each value by `_fixed_forces`' operations). The turn of the rest shape and of
    the normals, in the order of the numpy expressions they replaced (the same bits):
    turned = (rest - pivot) @ rot.T + pivot; base = rest + offset;
    target = base + w ((turned + offset @ rot.T) + slide - base); shape = rest + w ((turned + slide) - rest);
    normal = the unit rows of n + w (n @ rot.T - n) (squares summed left to right, as numpy's
    reduction over a row of three). rest, offset, normal3 (3, N): by coordinate
    (`Simulator._by_coordinate`), so the passes over the vertices, square roots and divisions
    included, are vector code, into tmp (10, N); then one pass over the rows lays out the target,
    the shape and the normals and makes the constant forces from them (four passes over the rows
    before: 49 -> 45 us alone on the scanned head, where a moving jaw makes them every tick). A
    normal turned to zero length raises ZeroDivisionError."""
    n = rest.shape[1]
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    p0, p1, p2 = pivot[0], pivot[1], pivot[2]
    s0, s1, s2 = slide[0], slide[1], slide[2]
    for i in range(n):  # the target and the shape
        w = weight[i]
        x0, x1, x2 = rest[0, i], rest[1, i], rest[2, i]
        o0, o1, o2 = offset[0, i], offset[1, i], offset[2, i]
        d0, d1, d2 = x0 - p0, x1 - p1, x2 - p2
        u0 = d0 * r00 + d1 * r01 + d2 * r02 + p0
        u1 = d0 * r10 + d1 * r11 + d2 * r12 + p1
        u2 = d0 * r20 + d1 * r21 + d2 * r22 + p2
        v0 = o0 * r00 + o1 * r01 + o2 * r02
        v1 = o0 * r10 + o1 * r11 + o2 * r12
        v2 = o0 * r20 + o1 * r21 + o2 * r22
        b0, b1, b2 = x0 + o0, x1 + o1, x2 + o2
        tmp[0, i] = b0 + w * (u0 + v0 + s0 - b0)
        tmp[1, i] = b1 + w * (u1 + v1 + s1 - b1)
        tmp[2, i] = b2 + w * (u2 + v2 + s2 - b2)
        tmp[3, i] = x0 + w * (u0 + s0 - x0)
        tmp[4, i] = x1 + w * (u1 + s1 - x1)
        tmp[5, i] = x2 + w * (u2 + s2 - x2)
    for i in range(n):  # the normals
        w = weight[i]
        n0, n1, n2 = normal3[0, i], normal3[1, i], normal3[2, i]
        t0 = n0 + w * (n0 * r00 + n1 * r01 + n2 * r02 - n0)
        t1 = n1 + w * (n0 * r10 + n1 * r11 + n2 * r12 - n1)
        t2 = n2 + w * (n0 * r20 + n1 * r21 + n2 * r22 - n2)
        length = math.sqrt((t0 * t0 + t1 * t1) + t2 * t2)
        tmp[6, i] = t0 / length
        tmp[7, i] = t1 / length
        tmp[8, i] = t2 / length
        tmp[9, i] = length
    with_shape = shape.shape[0] > 0
    with_fixed = fixed.shape[0] > 0
    for i in range(n):
        if tmp[9, i] == 0.0:
            raise ZeroDivisionError("a support normal turned to zero length")
        g0, g1, g2 = tmp[0, i], tmp[1, i], tmp[2, i]
        m0, m1, m2 = tmp[6, i], tmp[7, i], tmp[8, i]
        target[i, 0] = g0
        target[i, 1] = g1
        target[i, 2] = g2
        normal[i, 0] = m0
        normal[i, 1] = m1
        normal[i, 2] = m2
        if with_shape:
            shape[i, 0] = tmp[3, i]
            shape[i, 1] = tmp[4, i]
            shape[i, 2] = tmp[5, i]
        if with_fixed:  # `_fixed_forces`' row
            _fixed_row(i, g0, g1, g2, m0, m1, m2, w3, kr, kn, fixed)


@numba.njit(**KERNEL)
def _place(x, held, target):  # type: ignore[no-untyped-def]
    """x[held] = target[held] without numpy's gathered copy."""
    for k in range(held.shape[0]):
        i = held[k]
        for d in range(3):
            x[i, d] = target[i, d]


@numba.njit(**KERNEL)
def _open_pose(a, s, c, jaw, slide_one, rot, slide, rest, offset, normal3, pivot, weight, target, shape, normal, tmp,  # type: ignore[no-untyped-def]
               w3, kr, kn, fixed, x, held):
    """A new jaw opening (no thrust, no sideways move) in one call: `jaw_motion`'s rotation into
    rot (3, 3) and slide (3,) = jaw * slide_one, then `_jaw_pose`, then the held nodes' rows of x
    (when x has rows) onto the target (`_place`). The rotation's entries by `jaw_rotation`'s
    operations in its order from the unit axis a, s = sin(angle), c = 1 - cos(angle) made by
    Python's math (the same bits): the matrix, the slide, the pose and the placement were four
    calls and ~60 small Python operations a tick while the jaw moves."""
    _open_motion(a, s, c, jaw, slide_one, rot, slide)
    _jaw_pose(rest, offset, normal3, pivot, weight, rot, slide, target, shape, normal, tmp, w3, kr, kn, fixed)
    if x.shape[0] > 0:
        _place(x, held, target)


@numba.njit(inline="always")
def _open_motion(a, s, c, jaw, slide_one, rot, slide):  # type: ignore[no-untyped-def]
    """`jaw_motion` of an opening alone into rot (3, 3) and slide (3,), by `jaw_rotation`'s
    operations in its order (`_open_pose`)."""
    a0, a1, a2 = a[0], a[1], a[2]
    m0, m1, m2 = -a0, -a1, -a2
    rot[0, 0] = (1.0 + s * 0.0) + c * ((0.0 * 0.0 + m2 * a2) + a1 * m1)
    rot[0, 1] = (0.0 + s * m2) + c * ((0.0 * m2 + m2 * 0.0) + a1 * a0)
    rot[0, 2] = (0.0 + s * a1) + c * ((0.0 * a1 + m2 * m0) + a1 * 0.0)
    rot[1, 0] = (0.0 + s * a2) + c * ((a2 * 0.0 + 0.0 * a2) + m0 * m1)
    rot[1, 1] = (1.0 + s * 0.0) + c * ((a2 * m2 + 0.0 * 0.0) + m0 * a0)
    rot[1, 2] = (0.0 + s * m0) + c * ((a2 * a1 + 0.0 * m0) + m0 * 0.0)
    rot[2, 0] = (0.0 + s * m1) + c * ((m1 * 0.0 + a0 * a2) + 0.0 * m1)
    rot[2, 1] = (0.0 + s * a0) + c * ((m1 * m2 + a0 * 0.0) + 0.0 * a0)
    rot[2, 2] = (1.0 + s * 0.0) + c * ((m1 * a1 + a0 * m0) + 0.0 * 0.0)
    for d in range(3):
        slide[d] = jaw * slide_one[d]


@numba.njit(**KERNEL)
def _grid_pose(a, s, c, jaw, slide_one, rot, slide, grid, w3, kr, kn, target, normal, fixed, x, held):  # type: ignore[no-untyped-def]
    """A new jaw opening (0 < jaw <= 1, no thrust, no sideways move) with its constants read from
    a grid (`Simulator.constants_from_grid`): rot and slide as `_open_pose` makes them (the margin
    bending's turn), then eq 9's target and the support normals, each linear between the grid's two
    openings about `jaw` (grid (openings, 2, N, 3) float32: `_pose_grid`; read in float64), the
    normals brought back to unit length by a Newton step of 1 / sqrt (they are shorter by <= 4e-5:
    left at 1e-9), the constant forces without muscles from those rows as `_fixed_forces` makes
    them (made from the rows, not read: the support's constant side must turn with its side on x,
    or it pulls the skin by the normals' error times the distance from the origin), then the held
    nodes' rows of x onto the target. A pass over the values laid flat, then one over the rows: no
    turn, square root or division (42 -> 30 us alone on the scanned head, 50 -> 35 after 12 MB
    written)."""
    _open_motion(a, s, c, jaw, slide_one, rot, slide)
    steps = grid.shape[0] - 1
    t = jaw * steps
    k = min(int(t), steps - 1)
    f = t - k
    ta, tb = grid[k, 0].reshape(-1), grid[k + 1, 0].reshape(-1)
    na, nb = grid[k, 1].reshape(-1), grid[k + 1, 1].reshape(-1)
    to, no = target.reshape(-1), normal.reshape(-1)
    for p in range(to.shape[0]):  # (laid flat: vector code)
        u = float(ta[p])
        to[p] = u + f * (float(tb[p]) - u)
        u = float(na[p])
        no[p] = u + f * (float(nb[p]) - u)
    for i in range(target.shape[0]):
        g0, g1, g2 = target[i, 0], target[i, 1], target[i, 2]
        m0, m1, m2 = normal[i, 0], normal[i, 1], normal[i, 2]
        e = 1.5 - 0.5 * ((m0 * m0 + m1 * m1) + m2 * m2)
        m0 *= e
        m1 *= e
        m2 *= e
        normal[i, 0] = m0
        normal[i, 1] = m1
        normal[i, 2] = m2
        _fixed_row(i, g0, g1, g2, m0, m1, m2, w3, kr, kn, fixed)
    if x.shape[0] > 0:
        _place(x, held, target)


@numba.njit(**KERNEL)
def _active(values, is_muscle, act, val):  # type: ignore[no-untyped-def]
    """The muscle channels whose value is not 0, in order, into act[:k] and their values into
    val[:k]; returns k (numpy's flatnonzero and gather of the same, without their four arrays)."""
    k = 0
    for c in range(values.shape[0]):
        if is_muscle[c] and values[c] != 0.0:
            act[k] = c
            val[k] = values[c]
            k += 1
    return k


_NOTHING = object()  # (`Simulator._recall_contact`: no memory known to be held)


class JawTurn(NamedTuple):
    """The jaw's turn of the rest shape (`jaw_motion`): what the implicit step's margin bending
    makes its rest side from when `Simulator.bending_turned` (sim.implicit.ImplicitStepper.turn_basis)."""

    rot: np.ndarray  # (3, 3), contiguous float64
    slide: np.ndarray  # (3,) cm


@dataclass(frozen=True)
class GuardEvent:
    """The blow-up guard fired at simulated time `time` (s) for `reason`; the state was restored to
    the start of that frame with zero velocity."""

    time: float
    reason: str


def jaw_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix about a unit axis (Rodrigues): I + sin(angle) K + (1 - cos(angle)) K K, with
    K the axis's cross-product matrix. Spelled out on Python floats, each entry by the operations
    numpy's `np.eye(3) + s * k + c * times3(k, k)` does in its order (the same bits), because a
    moving jaw makes it every tick: 0.05 ms of small numpy operations, 4 us so."""
    a0, a1, a2 = float(axis[0]), float(axis[1]), float(axis[2])
    m0, m1, m2 = -a0, -a1, -a2  # K = ((0, -a2, a1), (a2, 0, -a0), (-a1, a0, 0))
    s = math.sin(angle)
    c = 1.0 - math.cos(angle)
    # entry (i, j): (I_ij + s K_ij) + c ((K_i0 K_0j + K_i1 K_1j) + K_i2 K_2j), the zeros multiplied
    # as written (a zero's sign can decide a sum's): written out, 4 us a call less than by loops
    return np.array((
        ((1.0 + s * 0.0) + c * ((0.0 * 0.0 + m2 * a2) + a1 * m1), (0.0 + s * m2) + c * ((0.0 * m2 + m2 * 0.0) + a1 * a0),
         (0.0 + s * a1) + c * ((0.0 * a1 + m2 * m0) + a1 * 0.0)),
        ((0.0 + s * a2) + c * ((a2 * 0.0 + 0.0 * a2) + m0 * m1), (1.0 + s * 0.0) + c * ((a2 * m2 + 0.0 * 0.0) + m0 * a0),
         (0.0 + s * m0) + c * ((a2 * a1 + 0.0 * m0) + m0 * 0.0)),
        ((0.0 + s * m1) + c * ((m1 * 0.0 + a0 * a2) + 0.0 * m1), (0.0 + s * a0) + c * ((m1 * m2 + a0 * 0.0) + 0.0 * a0),
         (1.0 + s * 0.0) + c * ((m1 * a1 + a0 * m0) + 0.0 * 0.0))))


def jaw_slide(model: FaceModel) -> np.ndarray:
    """(3,) cm: the mandible's translation at jaw = 1, forward (perpendicular to the hinge axis, in
    the horizontal plane of the project frame, +Y up) and down by params.jaw_slide_angle, of length
    params.jaw_max_slide scaled by the face's size."""
    p = model.params
    axis = np.asarray(model.jaw_axis, dtype=np.float64)
    up = np.array([0.0, 1.0, 0.0])
    forward = np.cross(axis, up)
    norm = norm3(forward)
    if norm < 1e-9:
        return np.zeros(3)
    forward /= norm
    direction = math.cos(p.jaw_slide_angle) * forward - math.sin(p.jaw_slide_angle) * up
    return p.jaw_max_slide * _face_scale(model) * direction


class Simulator:
    """Advances a FaceState by whole frames of frame_dt seconds under a FaceControl.

    wrinkles: fill state.surface with the wrinkle bulges (sim.wrinkles) after each frame; turn off
    when only the dynamics matter (benchmarks, analysis): surface then equals positions."""

    def __init__(self, model: FaceModel, frame_dt: float = 1.0 / 60.0, wrinkles: bool = True,
                 method: str = "auto") -> None:
        self.model = model
        self.wrinkles = wrinkles
        self._wrinkle: Callable[[FaceModel, FaceState], None] | None = None  # (`_surface`: imported once)
        if wrinkles and model.rig.wrinkles:  # build the wrinkle layer and load its kernel now, not
            from sim.wrinkles.layer import warm_up as warm_up_wrinkles  # on the first live frame

            warm_up_wrinkles(model)
        self.frame_dt = float(frame_dt)
        p = model.params
        visc = float(np.max(model.spring_damping / np.maximum(model.spring_k_low, 1e-30)))
        self.stable_dt = stable_step(model.omega_max, p.mass_damping, visc, p.high_ratio)
        self.rk2_substeps = max(1, math.ceil(self.frame_dt / (SAFETY * self.stable_dt)))
        if method == "auto" and getattr(model.rig, "integrator", "auto") != "auto":
            method = model.rig.integrator  # the face asks for one (sim.model.FaceRig.integrator)
        if method == "auto":
            work = self.rk2_substeps * len(model.spring_indices)
            method = "rk2" if work <= RK2_WORK_LIMIT else "implicit"
        if method not in ("rk2", "implicit"):
            raise ValueError(f"unknown integration method {method!r}; valid: auto, rk2, implicit")
        self.method = method
        self._implicit = None
        self._margins = margin_pairs(model.mesh, model.rest)
        if method == "rk2":
            self.substeps = self.rk2_substeps
        else:
            from sim.implicit import ImplicitStepper, implicit_substeps

            self.substeps = implicit_substeps(model, self.frame_dt)
        self.dt = self.frame_dt / self.substeps
        if method == "implicit":
            from sim.prepared import prepared

            self._implicit = ImplicitStepper(model, self.dt, prepared(model, self.dt))
        self.guard_events: list[GuardEvent] = []
        n = model.n_vertices
        self._free = np.ascontiguousarray(~model.held)
        self._inv_m = np.ascontiguousarray(np.where(self._free, 1.0 / model.mass, 0.0))  # 0: held
        # writeable contiguous copies: one numba signature (the warm-up's) for every call; springs
        # in vertex order (a fixed permutation, so still deterministic) for cache locality
        order = np.lexsort((model.spring_indices[:, 1], model.spring_indices[:, 0]))
        self._springs = np.array(model.spring_indices[order], dtype=np.int32, order="C")
        # the RK2 kernel's flat indices (3 x node), unsigned: no negative-index wraparound in the loop
        self._si3 = np.ascontiguousarray(3 * self._springs[:, 0], dtype=np.uint32)
        self._sj3 = np.ascontiguousarray(3 * self._springs[:, 1], dtype=np.uint32)
        self._work = np.zeros((9, len(self._springs)))
        self._rest_len = np.array(model.spring_rest_length[order], order="C")
        self._k_low_now = np.array(model.spring_k_low[order], order="C")  # `_k_low`
        self._k_high = np.array(model.spring_k_high[order], order="C")
        self._k_damp = np.array(model.spring_damping[order], order="C")
        self._k_low_base = self._k_low_now.copy()
        self._k_low_scale = 1.0  # k_low's scale at the skin's age (`_age_skin`)
        self._k_low_made = 1.0  # the scale `_k_low_now` was multiplied by
        self._k_high_base = self._k_high.copy()
        self._k_high_scale = 1.0  # the scale of `_k_high` (`_age_skin`)
        self._kr = np.array(model.rest_stiffness, order="C")
        self._c = np.array(model.damping, order="C")
        self._kn = np.array(model.support_stiffness, order="C")
        self._eyes = (np.array(model.eye_contact, dtype=np.int64), np.array(model.eye_contact_eye, dtype=np.int64),
                      np.array(model.mesh.eye_centers, dtype=np.float64, order="C"),
                      float(model.eye_contact_radius))
        self._normal = np.array(model.rest_normal, order="C")
        self._threshold = float(model.strain_threshold)
        self._skin_age: float | None = None  # the age the springs were last scaled for
        self._ext = np.zeros((n, 3))
        self._ext_values: np.ndarray | None = None  # the channel values self._ext was made for
        self._saved_x = np.zeros((n, 3))
        self._held = np.flatnonzero(model.held)
        # the guard's measure split between the implicit step (the free nodes) and `_held_deviation`
        self._split_check = self._implicit is not None and len(self._implicit.free) + len(self._held) == n
        self._is_muscle = np.array([s.kind == "muscle" for s in model.channels], dtype=np.bool_)
        self._weight = np.ascontiguousarray(model.weight, dtype=np.float64)
        if self._implicit is not None and self._implicit._resp.shape[0] < len(model.channels):
            raise ValueError("the implicit step's muscle responses do not cover the face's channels")
        self._ext_const = np.zeros((n, 3))  # the implicit step's constant forces without the muscles
        self._const_jaw: tuple[float, float, float] | None = None  # the jaw pose they were made for
        self._last_key: tuple[object, object] | None = None  # the last step's jaw pose and skin age
        self._moving = True  # they changed in the last step
        #: the implicit step sums every muscle's force into the frame's constant forces, as before
        #: the muscles entered as responses: set by a replay of a take recorded then, so it keeps
        #: its bits (puppet.replay; the results differ from the responses' only by rounding)
        self.muscles_summed = False
        #: the lids follow the eyes' turn (`sim.gaze_lids`): cleared by a replay of a take recorded
        #: before they did, so it keeps its bits (puppet.replay)
        self.lids_follow_gaze = True
        #: the upper and lower lids held to the turning globe apart (`sim.gaze_lids.UPPER`, `LOWER`):
        #: cleared by a replay of a take recorded before (no "lid coupling" in its header), whose
        #: lids were held alike, so it keeps its bits (puppet.replay)
        self.lids_apart = True
        self._couplings = lid_couplings(model)  # (alike, apart)
        #: the tissue round the globe carried by the turning eye (`sim.gaze_lids.tissue_fields`, the
        #: rig's `gaze`), with the lids apart: cleared by a replay of a take recorded before (no "gaze
        #: tissue" in its header), so it keeps its bits (puppet.replay)
        self.gaze_tissue = True
        self._tissue = tissue_fields(model)  # None: the face has none
        self._gaze = (0.0, 0.0, 0.0)  # the gaze (yaw, pitch, vergence) of the last frame
        # the implicit step's responses to the gaze's fields follow the muscles', the lids alike's,
        # apart's, then apart's with the tissue (sim.implicit.gaze_responses)
        c = len(model.channels)
        self._gaze_rows_of = tuple(np.arange(c + j * N_BASIS, c + (j + 1) * N_BASIS, dtype=np.int64) for j in range(3))
        if self._implicit is not None and self._implicit._resp.shape[0] < c + 3 * N_BASIS:
            raise ValueError("the implicit step's responses do not cover the gaze's pull on the lids")
        self._yaw_i = CHANNEL_INDEX["eyes_yaw"]
        self._pitch_i = CHANNEL_INDEX["eyes_pitch"]
        self._verge_i = CHANNEL_INDEX["eyes_vergence"]
        self._jaw: tuple[float, float, float] | None = None  # the jaw pose the target and normals were set for
        self._slide_one = jaw_slide(model)  # the condyles' slide at jaw = 1 (`jaw_motion`)
        self._axis = np.array(model.jaw_axis, dtype=np.float64)  # (`_set_opening`)
        self._base_threshold = float(model.strain_threshold)
        self._target_shape = model.rest.shape
        self._motion_pose: tuple[float, float, float] | None = None  # `_jaw_motion`'s last pose
        self._motion: tuple[np.ndarray, np.ndarray] = (np.eye(3), np.zeros(3))
        self._target = model.rest + model.rest_offset
        self._shape: np.ndarray | JawTurn = np.array(model.rest)
        self._force = np.zeros((n, 3))  # the RK2 kernel's force scratch
        self._xm = np.zeros((n, 3))
        self._vm = np.zeros((n, 3))
        self._bound = BLOWUP_DISPLACEMENT * _face_scale(model)
        self._jaw_i = CHANNEL_INDEX["jaw"]
        self._jaw_forward_i = CHANNEL_INDEX["jaw_forward"]
        self._jaw_side_i = CHANNEL_INDEX["jaw_sideways"]
        self._age_i = CHANNEL_INDEX["age"]
        self._tongue_i = CHANNEL_INDEX["tongue_out"]
        self._head_i = (CHANNEL_INDEX["head_yaw"], CHANNEL_INDEX["head_pitch"], CHANNEL_INDEX["head_roll"])
        self._pivot = np.array(model.jaw_pivot, dtype=np.float64)
        self._no_rows = np.zeros((0, 3))
        self._act = np.zeros(len(model.channels), dtype=np.int64)  # `_muscles`' active channels
        self._act_val = np.zeros(len(model.channels))
        #: the implicit step starts from the jaw's opening and the skin's age of the state's last
        #: step, and the jaw's move since enters as the difference of its precomputed responses
        #: (`sim.implicit.ImplicitStepper.jaw_response`): a moved jaw or age needs no whole step at
        #: the input (`prepare` computes the rest ahead), and the skin's stiffness follows the age
        #: one step later. False: the step computes everything at the control's pose and age, as
        #: takes recorded before it did (puppet.replay sets it for them, so they keep their bits).
        self.jaw_responses = True
        #: the implicit step's margin bending makes its rest side at an open jaw from the jaw's
        #: turn (`JawTurn`, sim.implicit.ImplicitStepper.turn_basis: three values a row) instead of
        #: the product of its matrix with the turned rest shape; the same forces up to rounding.
        #: False: the product, as takes recorded before (puppet.replay sets it for them, for their
        #: bits). Set before the first step.
        self.bending_turned = True
        self._last_pose: tuple[float, float, float] | None = None  # the last step's jaw pose
        #: the implicit step's constants at a jaw opening (eq 9's target, the support normals, the
        #: constant forces; not the margin bending's turn) read linearly between openings 1 / JAW_GRID
        #: apart, kept in float32 (`_grid_pose`, `_pose_grid`), instead of the mandible's turn of every
        #: vertex at each new opening: the target off the turn's arc by ~4 um at a chin 10 cm from
        #: the hinge, the normals shorter by <= 4e-5; other bits. False: the turn, as takes recorded
        #: before (puppet.replay sets it for them, for their bits). Only where `_opening_fast`.
        self.constants_from_grid = True
        self._grid: np.ndarray | None = None  # (`_pose_grid`: made below for the implicit step)
        # the turns' inputs by coordinate (`_jaw_pose`: vector code over the vertices)
        self._rest3, self._offset3 = self._by_coordinate(model.rest), self._by_coordinate(model.rest_offset)
        self._normal3 = self._by_coordinate(model.rest_normal)
        self._jaw_weight = np.array(model.jaw_weight, dtype=np.float64)
        self._turn_tmp = np.zeros((10, n))  # (`_jaw_pose`'s)
        self._turned_normal = np.zeros((n, 3))  # the normals `_jaw_turned` makes on the way
        if self._implicit is not None:
            # (the poses' grid now, not at the live show's first opening)
            self._implicit.jaw_resp, self._implicit.jaw_slope, self._grid = _jaw_arrays(self)
            self._implicit.turn_basis(self._jaw_weight, np.asarray(model.jaw_pivot, dtype=np.float64))
            self._implicit._single(True)  # (the jaw's float32 responses too: 8.6 MB cast, ~4 ms)
        self._rest_shape = np.array(model.rest)  # the margin bending's rest shape at rest (`bending_turned`)
        self._recalled: object = _NOTHING  # the memory the contact's arrays hold (`_recall_contact`)

    @property
    def symmetric_solve(self) -> bool:
        """The implicit step's substeps solve from the symmetric factor alone (L and D:
        `sim.supernodal._sym_sweeps`, the same positions up to rounding, U's values unread). False:
        from L and U, as takes recorded before (puppet.replay sets it for them, for their bits).
        Always False for the explicit integrator, and for factors whose rows and columns were
        permuted differently (then L and U whatever is asked). Set before the first step."""
        return self._implicit is not None and self._implicit.symmetric_solve

    @symmetric_solve.setter
    def symmetric_solve(self, on: bool) -> None:
        if self._implicit is not None:  # (factors permuted differently by rows and columns: L and U always)
            self._implicit.symmetric_solve = bool(on) and self._implicit.solver.symmetric

    @property
    def single_responses(self) -> bool:
        """The implicit step reads the inputs' precomputed responses (muscles, gaze, jaw) rounded
        to float32 (`sim.implicit.ImplicitStepper.single_responses`; sums in float64). False: in
        float64, as takes recorded before (puppet.replay sets it for them, for their bits)."""
        return self._implicit is not None and self._implicit.single_responses

    @single_responses.setter
    def single_responses(self, on: bool) -> None:
        if self._implicit is not None:
            self._implicit.single_responses = bool(on)

    @property
    def _opening_fast(self) -> bool:
        """Whether `_set_jaw` makes a jaw opening by `_set_opening`: the implicit step with its
        bending from the turn and its muscles as responses (what it makes then)."""
        return self._implicit is not None and self.bending_turned and not self.muscles_summed

    @staticmethod
    def _by_coordinate(rows: np.ndarray) -> np.ndarray:
        """(3, N) writeable contiguous copy of (N, 3) rows: the same values, one numba signature."""
        return np.array(np.asarray(rows, dtype=np.float64).T, order="C")

    # -- the force terms that are constant over a frame

    def rest_target(self, jaw: float, offset: bool = True, forward: float = 0.0,
                    sideways: float = 0.0) -> np.ndarray:
        """Eq 9's rest positions with the jaw opened by `jaw` (0..1), thrust by `forward` (0..1) and
        moved sideways by `sideways` (-1..1), plus the gravity pre-stress offset
        (`FaceModel.rest_offset`, turned with the jaw the same way; offset=False: the rest shape
        turned with the jaw alone), (N,3) cm."""
        target, shape, _ = self._jaw_turned((jaw, forward, sideways), shape=not offset)
        return target if offset else shape  # type: ignore[return-value]

    def _jaw_turned(self, pose: tuple[float, float, float], shape: bool,
                    normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(eq 9's target, the rest shape turned with the jaw or None unless `shape`, the jaw's
        rotation or None at rest) for the jaw pose (open, forward, sideways): the mandible's turn
        and slide computed once for all three (`jaw_motion`); away from rest the support normals
        turned with it into `normals` (N,3) when given (`_jaw_pose`)."""
        m = self.model
        if pose == (0.0, 0.0, 0.0):
            return np.array(m.rest + m.rest_offset), (np.array(m.rest) if shape else None), None
        rot, slide = self._jaw_motion(pose)
        target = np.empty_like(m.rest)
        turned_shape = np.empty_like(m.rest) if shape else self._no_rows
        _jaw_pose(self._rest3, self._offset3, self._normal3, self._pivot, self._jaw_weight, rot, slide, target,
                  turned_shape, self._turned_normal if normals is None else normals, self._turn_tmp, self._weight,
                  self._kr, self._kn, self._no_rows)
        return target, (turned_shape if shape else None), rot

    def _jaw_motion(self, pose: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
        """`jaw_motion` at `pose`, kept for the last pose asked: a moving jaw's step places the held
        nodes at the pose the next step starts from, whose constants `prepare` then makes (the
        same arrays; 0.07 ms of small numpy operations each, on the scanned head), as contiguous
        float64 arrays (the kernels' one signature)."""
        if pose != self._motion_pose:
            rot, slide = jaw_motion(self.model, *pose, slide_one=self._slide_one)
            self._motion = (np.ascontiguousarray(rot, dtype=np.float64), np.ascontiguousarray(slide, dtype=np.float64))
            self._motion_pose = pose
        return self._motion

    def _set_jaw(self, pose: tuple[float, float, float], place: np.ndarray | None = None) -> None:
        """The jaw-dependent frame constants: eq 9's target (`rest_target`) and the support normals
        n_i (the rest normals turned with the jaw like the target), recomputed only when the jaw
        moves; for the implicit integrator also the reference of its margin bending term (`sim.implicit`)
        and, where its muscles enter as responses, its constant forces (`_constants`), all from one
        kernel (`_jaw_pose`) away from rest. place: positions whose held nodes are put on the
        pose's target (`_place_held`)."""
        if pose == self._jaw:
            if place is not None:
                _place(place, self._held, self._target)
            return
        if pose[1] == 0.0 and pose[2] == 0.0 and pose[0] and self._opening_fast:
            self._set_opening(pose, place)
            return
        m = self.model
        implicit = self._implicit is not None
        turned = implicit and self.bending_turned
        if pose == (0.0, 0.0, 0.0):
            self._target, shape, _ = self._jaw_turned(pose, shape=implicit and not turned)
            if turned:  # (at rest the product with the rest shape: the bits of a take without the jaw stay)
                self._shape = self._rest_shape
            elif shape is not None:
                self._shape = shape
            self._normal[...] = m.rest_normal
            self._jaw = pose
            return
        rot, slide = self._jaw_motion(pose)
        target = np.empty_like(m.rest)
        shape = np.empty_like(m.rest) if implicit and not turned else self._no_rows
        fixed = self._ext_const if implicit and not self.muscles_summed else self._no_rows
        _jaw_pose(self._rest3, self._offset3, self._normal3, self._pivot, self._jaw_weight, rot, slide, target, shape,
                  self._normal, self._turn_tmp, self._weight, self._kr, self._kn, fixed)
        self._target = target
        if turned:
            self._shape = JawTurn(rot, slide)
        elif implicit:
            self._shape = shape
        self._jaw = pose
        if len(fixed):
            self._const_jaw = pose
        if place is not None:
            _place(place, self._held, target)

    def _set_opening(self, pose: tuple[float, float, float], place: np.ndarray | None) -> None:
        """`_set_jaw` for a jaw opened by pose[0] (not 0) with no thrust and no sideways move, on the
        implicit step with its bending from the turn and its muscles as responses (a moving jaw's
        every tick): `jaw_motion`, `_jaw_pose` and the held nodes' placement from one kernel
        (`_open_pose`), the same values."""
        jaw = pose[0]
        angle = jaw * self.model.params.jaw_max_angle
        rot, slide, target = np.empty((3, 3)), np.empty(3), np.empty(self._target_shape)
        if self.constants_from_grid and jaw <= 1.0 and jaw > 0.0:
            if self._grid is None:
                self._grid = self._pose_grid()
            _grid_pose(self._axis, math.sin(angle), 1.0 - math.cos(angle), jaw, self._slide_one, rot, slide,
                       self._grid, self._weight, self._kr, self._kn, target, self._normal, self._ext_const,
                       self._no_rows if place is None else place, self._held)
            self._target = target
            self._shape = JawTurn(rot, slide)
            self._jaw = self._const_jaw = pose
            return
        _open_pose(self._axis, math.sin(angle), 1.0 - math.cos(angle), jaw, self._slide_one, rot, slide, self._rest3,
                   self._offset3, self._normal3, self._pivot, self._jaw_weight, target, self._no_rows, self._normal,
                   self._turn_tmp, self._weight, self._kr, self._kn, self._ext_const,
                   self._no_rows if place is None else place, self._held)
        self._target = target
        self._shape = JawTurn(rot, slide)
        self._jaw = self._const_jaw = pose

    def _pose_grid(self) -> np.ndarray:
        """(JAW_GRID + 1, 2, N, 3) float32: eq 9's target and the support normals at the openings
        k / JAW_GRID (`_grid_pose` reads them linearly between two): the opening 0's as the rest
        pose has them, the others by `_open_pose` (33 poses: ~2 ms on the scanned head, once per
        simulator)."""
        m, n = self.model, self.model.n_vertices
        grid = np.zeros((JAW_GRID + 1, 2, n, 3), dtype=np.float32)
        target, normal, fixed = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        rot, slide, none = np.empty((3, 3)), np.empty(3), np.zeros((0, 3))
        for k in range(JAW_GRID + 1):
            if k == 0:
                target[...] = m.rest + m.rest_offset
                normal[...] = m.rest_normal
                _fixed_forces(self._weight, self._kr, target, self._kn, normal, fixed)
            else:
                jaw = k / JAW_GRID
                angle = jaw * m.params.jaw_max_angle
                _open_pose(self._axis, math.sin(angle), 1.0 - math.cos(angle), jaw, self._slide_one, rot, slide,
                           self._rest3, self._offset3, self._normal3, self._pivot, self._jaw_weight, target, none,
                           normal, self._turn_tmp, self._weight, self._kr, self._kn, fixed, none, self._held)
            grid[k, 0], grid[k, 1] = target, normal
        return grid

    def external_forces(self, control: FaceControl) -> np.ndarray:
        """Every force term that does not depend on x or v within a frame, (N,3) dyn (a buffer the
        simulator reuses): see `_constant_forces`."""
        v = control.values
        self._set_jaw((float(v[self._jaw_i]), float(v[self._jaw_forward_i]), float(v[self._jaw_side_i])))
        if self._ext_values is not None and np.array_equal(v, self._ext_values):
            return self._ext  # the same channel values as last frame (a held pose): the same forces
        mm = self.model.muscle_matrix
        _constant_forces(mm.indptr, mm.indices, mm.data, control.values, self._is_muscle, self._weight,
                         self._kr, self._target, self._kn, self._normal, self._ext)
        gaze = self._set_gaze(v)
        if gaze != (0.0, 0.0, 0.0):
            idx, eye, gain, pitch_gain = self._couplings[self.lids_apart]
            gaze_forces(self.model.rest, idx, eye, gain, self.model.mesh.eye_centers, *gaze, self._ext, pitch_gain)
            if self._tissue is not None and self.lids_apart and self.gaze_tissue:
                add_tissue_forces(self._tissue, *gaze, self._ext)
        self._ext_values = np.array(v)
        return self._ext

    def _set_gaze(self, v: np.ndarray) -> tuple[float, float, float]:
        """The gaze (yaw, pitch, vergence) the lids are pulled by this frame (zeros unless they
        follow it)."""
        if self.lids_follow_gaze and len(self._couplings[0][0]):
            self._gaze = (min(1.0, max(-1.0, float(v[self._yaw_i]))), min(1.0, max(-1.0, float(v[self._pitch_i]))),
                          min(1.0, max(-1.0, float(v[self._verge_i]))))
        else:
            self._gaze = (0.0, 0.0, 0.0)
        return self._gaze

    def _constants(self, pose: tuple[float, float, float]) -> np.ndarray:
        """For the implicit step: the constant forces without the muscles at the jaw `pose`
        (`_constant_forces` with none active: recomputed only when the pose changes)."""
        self._set_jaw(pose)
        if self._const_jaw != self._jaw:
            _fixed_forces(self._weight, self._kr, self._target, self._kn, self._normal, self._ext_const)
            self._const_jaw = self._jaw
        return self._ext_const

    def _muscles(self, control: FaceControl) -> tuple[np.ndarray, np.ndarray]:
        """The active muscle channels with their activations (their forces enter the implicit step
        as responses, `sim.implicit.muscle_responses`)."""
        v = control.values
        if v.shape == self._is_muscle.shape and v.dtype == np.float64 and v.flags.c_contiguous:
            k = _active(v, self._is_muscle, self._act, self._act_val)
            act, val = self._act[:k], self._act_val[:k]  # (rewritten by the next call)
        else:
            act = np.flatnonzero(self._is_muscle & (v != 0.0))
            val = np.ascontiguousarray(v[act], dtype=np.float64)
        gaze = self._set_gaze(v)
        if gaze != (0.0, 0.0, 0.0):  # the lids' pull by the turned eyes, as responses after the muscles'
            coef = basis_coefficients(*gaze)
            on = coef != 0.0  # (a look straight aside or up needs a quarter of them)
            rows = self._gaze_rows_of[self.lids_apart + (self.lids_apart and self.gaze_tissue)]
            act = np.concatenate([act, rows[on]])
            val = np.concatenate([val, coef[on]])
        return act, val

    def _start_pose(self, state: FaceState, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        """The jaw pose a step towards `pose` starts from (`jaw_responses`): the state's last
        opening, when only the opening moves and both lie on the responses' range; else `pose`."""
        if (pose[1] == 0.0 and pose[2] == 0.0 and 0.0 <= pose[0] <= 1.0 and 0.0 <= state.jaw <= 1.0
                and len(self._implicit.jaw_resp)):  # type: ignore[union-attr]
            return (float(state.jaw), 0.0, 0.0)
        return pose

    def _place_held(self, x: np.ndarray, pose: tuple[float, float, float]) -> None:
        """The held nodes onto eq 9's target at the jaw `pose`, with the jaw's constants made for
        that pose now (`_set_jaw`): the next step starts from it, and `prepare` finds them made
        (each row of the target is the same bits whichever rows are turned, so the held nodes'
        rows turned alone gave these very values; this spares that second turn, 0.04 ms a tick)."""
        self._set_jaw(pose, place=x)

    # -- stepping

    def step(self, state: FaceState, control: FaceControl, surface: bool = True) -> FaceState:
        """Advance `state` by one frame in place (and return it). On NaN or blow-up, restore the state
        at the start of the frame with zero velocity and append a GuardEvent. surface=False leaves
        state.surface (the wrinkles, drawn only) to a later `surface(state)`: the live loop marks the
        simulated state ready before it, so an input's latency does not wait for the drawing's layer."""
        x, v = state.positions, state.velocities
        checked: np.ndarray | None = None  # the target the guard checks against (None: the frame's)
        summed = self._implicit is None or self.muscles_summed
        values = control.values
        pose = (float(values[self._jaw_i]), float(values[self._jaw_forward_i]), float(values[self._jaw_side_i]))
        lagged = not summed and self.jaw_responses
        start = self._start_pose(state, pose) if lagged else pose
        if summed:
            ext, active = self.external_forces(control), None
        else:
            ext, active = self._constants(start), self._muscles(control)
        if x.shape == self._saved_x.shape and x.dtype == np.float64 and x.flags.c_contiguous:
            _save_hold(x, v, self._held, self._target, self._saved_x)  # (the copy and the hold in one call)
        else:
            np.copyto(self._saved_x, x)
            _hold(x, v, self._held, self._target)
        self._age_skin(state.age if lagged else float(values[self._age_i]))
        if self._implicit is None:
            _rk2_frame(x, v, self.substeps, self.dt, self._si3, self._sj3, self._rest_len, self._k_low,
                       self._k_high, self._k_damp, self._threshold, ext, self._kr, self._c, self._normal,
                       self._kn, self._inv_m, self._force, self._xm, self._vm, self._work, *self._eyes,
                       *self._margins)
        else:
            if self._implicit.margins is not None:  # the contact's memory is part of the state (a checkpoint's too)
                self._recall_contact(state.contact)
                self._recalled = _NOTHING  # (the step changes the contact's arrays)
            checked = self._target  # the guard measures the step against the pose it started from
            self._implicit.frame(x, v, self.substeps, ext, self._spring_constants(), self._normal,
                                 self._eyes, self._shape, key=(self._jaw, self._skin_age), active=active,
                                 summed=summed, jaw=None if start == pose else (start[0], pose[0]),
                                 check=checked if self._split_check else None)
            # a jaw or an age still moving will likely move again: `prepare` would be wasted then
            # (unless the step starts from the state's pose, `jaw_responses`)
            self._moving = (self._jaw, self._skin_age) != self._last_key
            self._last_key = (self._jaw, self._skin_age)
            self._last_pose = pose
            if start != pose:  # the held nodes follow the jaw to where the step moved it
                self._place_held(x, pose)
        if (checked is not None and self._implicit is not None
                and self._implicit.last_deviation is not None):  # (the free nodes measured in the step)
            reason = self._judge(_held_deviation(x, self._held, checked, self._implicit.last_deviation))
        else:
            reason = self._check(x, checked)
        if reason:
            x[...] = self._saved_x
            v[...] = 0.0
            if self._implicit is not None and self._implicit.margins is not None:
                self._implicit.margins.lam[...] = 0.0  # no contact force carried into the restart
            self.guard_events.append(GuardEvent(state.time + self.frame_dt, reason))
        if self._implicit is not None and self._implicit.margins is not None:
            state.contact = self._recalled = self._implicit.margins.memory()
        state.time += self.frame_dt
        values = control.values
        state.eye_yaw = float(values[self._yaw_i])
        state.eye_pitch = float(values[self._pitch_i])
        state.eye_vergence = float(values[self._verge_i])
        state.jaw = float(values[self._jaw_i])
        state.tongue_out = float(values[self._tongue_i])
        state.age = float(values[self._age_i])
        state.head_yaw = float(values[self._head_i[0]])
        state.head_pitch = float(values[self._head_i[1]])
        state.head_roll = float(values[self._head_i[2]])
        if surface:
            self._surface(state)
        return state

    def prepare(self, state: FaceState) -> None:
        """Compute ahead the part of the next step that no input changes (the implicit integrator's
        `predict`), for a `step` of this very state with the skin's age and the jaw as in the last
        step; the live loop calls it between ticks. A step given anything else does it itself:
        the same bits either way. Nothing for RK2. With `jaw_responses` the next step starts from the
        state's jaw opening and age, known now, whether they move or not; without, nothing while the
        jaw or the age is moving (the last step moved them: the next one likely will too, and the
        work would be wasted)."""
        if self._implicit is None or self.muscles_summed:
            return
        if self.jaw_responses:
            guess = self._last_pose if self._last_pose is not None else (float(state.jaw), 0.0, 0.0)
            self._constants(self._start_pose(state, guess))
            self._age_skin(state.age)
        elif self._jaw is None or self._const_jaw != self._jaw or self._moving:
            return
        if self._implicit.margins is not None:
            self._recall_contact(state.contact)
        self._implicit.predict(state.positions, state.velocities, self._ext_const,
                               self._spring_constants(),
                               self._normal, self._shape, (self._jaw, self._skin_age), ext_key=self._jaw)

    def _recall_contact(self, memory: np.ndarray | None) -> None:
        """The implicit step's contact arrays from a state's memory (`SolvedContact.recall`), unless
        they hold that very array's values already: the memory this simulator's last step made,
        or recalled last, with no step since (the live loop's prepare and step recalled the
        memory the step before had just made: two calls a tick for nothing)."""
        if memory is None or memory is not self._recalled:
            self._recalled = _NOTHING
            self._implicit.margins.recall(memory)  # type: ignore[union-attr]
            self._recalled = memory

    def surface(self, state: FaceState) -> None:
        """Fill state.surface for the positions of the last step (see `step`'s surface=False)."""
        self._surface(state)

    @property
    def _k_low(self) -> np.ndarray:
        """The springs' k_low at the skin's age: k_low_base times its scale (`_age_skin`),
        multiplied when the scale has changed since it was last asked."""
        if self._k_low_made != self._k_low_scale:
            np.multiply(self._k_low_base, self._k_low_scale, out=self._k_low_now)
            self._k_low_made = self._k_low_scale
        return self._k_low_now

    def _spring_constants(self) -> tuple:  # type: ignore[type-arg]
        """The springs as the implicit step takes them: (indices, rest lengths, k_low at the young
        skin, k_high, the strain threshold, k_low's scale at the skin's age)."""
        return (self._springs, self._rest_len, self._k_low_base, self._k_high, self._threshold, self._k_low_scale)

    def _age_skin(self, age: float) -> None:
        """Aged skin is softer at low strain and stiffens later (seed 003 section 2; the law is
        sim.wrinkles.aging.skin_params_for_age): rescale the springs when the age channel moves.
        k_h is never raised, so the stable substep stays valid."""
        if age == self._skin_age:
            return
        skin = aging.skin_params_for_age(age, self._base_threshold)  # (the module's: looked up at each call)
        self._k_low_scale = skin.k_low_scale  # (multiplied when `_k_low` is asked; the implicit step's kernel
        # multiplies each spring's as it reads it: the same products, 35k values a tick written less)
        high = min(skin.k_high_scale, 1.0)
        if high != self._k_high_scale:  # (the age law leaves k_h alone: skipped while the age moves)
            np.multiply(self._k_high_base, high, out=self._k_high)
            self._k_high_scale = high
        self._threshold = skin.strain_threshold
        self._skin_age = age

    def _surface(self, state: FaceState) -> None:
        """state.surface = positions plus the wrinkle bulges at state.age (sim.wrinkles), or the
        positions alone when the rig has no wrinkle lines."""
        if self.wrinkles and self.model.rig.wrinkles:
            if self._wrinkle is None:
                from sim.wrinkles.layer import apply_wrinkles

                self._wrinkle = apply_wrinkles
            self._wrinkle(self.model, state)
        else:
            state.surface[...] = state.positions

    def _check(self, x: np.ndarray, target: np.ndarray | None = None) -> str:
        return self._judge(_max_deviation(x, self._target if target is None else target))

    def _judge(self, dev: float) -> str:
        """The guard's verdict on the largest distance from the target (-1: not finite)."""
        if dev < 0.0:
            return "non-finite positions"
        if dev > self._bound:
            return f"displacement {dev:.3g} cm beyond {self._bound:.3g} cm"
        return ""

    def settle(self, state: FaceState, control: FaceControl, max_seconds: float = 5.0) -> float:
        """Step until no vertex moves faster than SETTLE_SPEED (after at least 0.1 s) or max_seconds
        have passed; returns the simulated seconds."""
        frames = 0
        limit = max(1, int(round(max_seconds / self.frame_dt)))
        while frames < limit:
            self.step(state, control)
            frames += 1
            if frames * self.frame_dt >= 0.1:
                speed = float(np.sqrt(np.max(np.sum(state.velocities**2, axis=1))))
                if speed < SETTLE_SPEED:
                    break
        return frames * self.frame_dt


#: the jaw's responses are made at the openings k / JAW_GRID (k = 0..JAW_GRID) and read linearly
#: between them: a grid step turns the mandible 1.0 degree at the default jaw_max_angle (0.55 rad),
#: which moves a chin 10 cm from the hinge off the chord by ~4 micrometres
JAW_GRID = 32
_JAW_EPS = 1e-4  # the opening's step of the target's central difference (the support's slope)


def _jaw_arrays(s: Simulator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The jaw's responses and their slopes at the grid's openings (`_jaw_grid`) and the poses at
    them (`Simulator._pose_grid`), made once per face and substep and kept with the integrator's
    prepared arrays (`sim.prepared.kept`: this process's memory, else the application's store, the
    face cache on disk): making them took 0.1-0.15 s of CPU at every start of the scanned head (66
    solves and 33 poses), reading them back ~0.02 s. The same arrays either way, so the same bits."""
    from sim.prepared import key_of, kept

    m, stepper = s.model, s._implicit
    assert stepper is not None
    p = m.params
    d = hashlib.sha256(f"jaw grid {JAW_GRID} eps={_JAW_EPS!r} h={float(s.dt).hex()} {key_of(stepper.prepared, m, s.dt)} "
                       f"{p.jaw_max_angle!r} {p.jaw_max_slide!r} {p.jaw_slide_angle!r}".encode())
    for arr in (m.rest, m.rest_offset, m.rest_normal, m.jaw_weight, m.jaw_pivot, m.jaw_axis, m.mesh.eye_centers,
                m.held, s._weight, s._kr, s._kn, s._springs, s._k_low_base, s._k_high_base, s._is_muscle):
        a = np.ascontiguousarray(arr)
        d.update(f"{a.dtype.str}{a.shape}".encode() + a.tobytes())
    nf, n = len(stepper.free), m.n_vertices
    want = {"resp": ((JAW_GRID + 1, nf, 3), np.float64), "slope": ((JAW_GRID + 1, nf, 3), np.float64),
            "pose": ((JAW_GRID + 1, 2, n, 3), np.float32)}

    def make() -> dict[str, np.ndarray]:
        grid, slope = _jaw_grid(s)
        return {"resp": grid, "slope": slope, "pose": s._pose_grid()}

    def check(a: dict[str, np.ndarray]) -> None:
        if set(a) != set(want):
            raise ValueError("not the jaw's arrays")
        for name, (shape, dtype) in want.items():
            arr = a[name]
            # as made: C-ordered and writable (the kernels' one compiled signature), finite
            if arr.shape != shape or arr.dtype != dtype or not arr.flags.c_contiguous or not arr.flags.writeable \
                    or not np.all(np.isfinite(arr)):
                raise ValueError(f"{name}: not the jaw's {shape} {np.dtype(dtype).name}")

    a = kept("jaw", d.hexdigest(), make, check)
    return a["resp"], a["slope"], a["pose"]


def _jaw_grid(s: Simulator) -> tuple[np.ndarray, np.ndarray]:
    """Two (JAW_GRID + 1, free nodes, 3) arrays at the grid's openings: the implicit step's response
    to the jaw's pose (`sim.implicit.ImplicitStepper.jaw_response`: eq 9's target, the margin
    bending's rest shape and the held nodes with their springs' pull, all turned with the jaw), and
    the slope in the opening of the normal support's response, k_n n (n . d target / d jaw). Made
    once per face and substep (2 (JAW_GRID + 1) solves: 0.17 s of CPU on the scanned head, 0.3 s
    at load 6) and kept (`_jaw_arrays`)."""
    m, stepper = s.model, s._implicit
    assert stepper is not None
    grid = np.zeros((JAW_GRID + 1, len(stepper.free), 3))
    # the springs from a held node to a free one: a step's local step (sim.implicit._pd_springs)
    # carries their rest direction along with the held end, so the matrix's pull k_h on the free end
    # is cancelled but for the axial stiffness (the step's derivative at rest: -k_h I + k_low u u^T
    # on top of the matrix's +k_h): the held edge moves the free skin by that, not by k_h
    held_at = np.asarray(m.held)
    sp_i, sp_j = s._springs[:, 0].astype(np.int64), s._springs[:, 1].astype(np.int64)
    cross = held_at[sp_i] != held_at[sp_j]
    free_end = np.where(held_at[sp_i[cross]], sp_j[cross], sp_i[cross])
    held_end = np.where(held_at[sp_i[cross]], sp_i[cross], sp_j[cross])
    u = m.rest[held_end] - m.rest[free_end]
    u /= np.linalg.norm(u, axis=1)[:, None]
    k_h, k_l = s._k_high_base[cross], s._k_low_base[cross]
    mm = m.muscle_matrix
    none = np.zeros_like(mm.indptr)
    ext, normal = np.zeros((m.n_vertices, 3)), np.array(m.rest_normal, dtype=np.float64)
    no_weight = np.zeros_like(s._weight)
    # the normal support k_n n n^T (target - x) keeps the normals of the step's start pose: turned
    # with the jaw, its constant side k_n n (n . target) and its side on x (sim.implicit._predict:
    # n (n . y)) change together and, with x near the target, cancel to first order (the constant
    # side alone would pull the whole skin by k_n times the normals' turn times its distance from
    # the origin); what is left is the target's move along the normals, the slope below
    no_support = np.zeros_like(s._kn)
    slope = np.zeros_like(grid)
    turned_normal = np.zeros_like(normal)
    for k in range(JAW_GRID + 1):
        target, shape, rot = s._jaw_turned((k / JAW_GRID, 0.0, 0.0), shape=True, normals=turned_normal)
        _constant_forces(none, mm.indices, mm.data, np.zeros(len(s._is_muscle)), s._is_muscle, no_weight,
                         s._kr, target, no_support, normal, ext)
        edge = target[held_end]
        pull = k_l[:, None] * u * np.einsum("ij,ij->i", u, edge)[:, None] - k_h[:, None] * edge
        rhs = ext.copy()
        np.add.at(rhs, free_end, pull)
        stepper.jaw_response(rhs, shape, target[s._held], grid[k])
        lo, hi = max(0.0, k / JAW_GRID - _JAW_EPS), min(1.0, k / JAW_GRID + _JAW_EPS)
        ahead, behind = s._jaw_turned((hi, 0.0, 0.0), shape=False)[0], s._jaw_turned((lo, 0.0, 0.0), shape=False)[0]
        tangent = (ahead - behind) / (hi - lo)
        if rot is None:
            normal[...] = m.rest_normal
        else:
            normal[...] = turned_normal  # (made with the pose's target: `_jaw_pose`)
        along = s._kn * np.einsum("ij,ij->i", normal, tangent)
        stepper.jaw_response(along[:, None] * normal, None, None, slope[k])
    return grid, slope


def _face_scale(model: FaceModel) -> float:
    """Inter-pupillary distance relative to 6.3 cm (1.0 for an average adult)."""
    ec = model.mesh.eye_centers
    return norm3(ec[0] - ec[1]) / 6.3
