"""A second integrator for big meshes: implicit Euler by one projective-dynamics iteration.

Explicit RK2 (the paper's method, `sim.integrator`) needs a step below ~2/omega_max, and omega_max
grows as 1/edge length: at 12k vertices that is ~80 substeps of ~80k springs per frame, far beyond a
real-time budget. Here each substep is one local/global iteration of projective dynamics
(Bouaziz et al. 2014) for implicit Euler:

- local: each spring s, at the predicted positions y = x + h v, gets a target vector d_s along its
  current direction whose length l_s makes k_h (r - l_s) equal the true biphasic tension T(r)
  (eqs 1-3): l_s = r - T(r) / k_h. The spring's term k_h |x_j - x_i - d_s|^2 then has exactly the
  true force at y and a Hessian that never changes.
- global: (M / h^2 + C / h + L(k_h) + diag(k_r)) x' = M / h^2 y + C / h x + sum_s k_h (e_j - e_i) d_s
  + k_r target + f_muscle + f_gravity, with L(k_h) the springs' graph Laplacian. The matrix is
  constant and the same for x, y and z, so it is factored once (sparse LU, scipy SuperLU) and a
  substep costs one spring pass and two triangular solves with 3 right-hand sides (laid out and
  swept by supernodes, `sim.supernodal`).
- the muscles enter as responses: the step is linear in their forces, so each muscle channel's
  A^-1 of its force (`muscle_responses`, made with the factors) times its activation is added to
  the solve of everything else (y, inertia, damping, the springs' local step, the fold guard, the
  support, the last contact forces: `_predict`; the jaw pose's constant forces, the held nodes).
  That solve depends on no muscle channel, so it can be made before the frame's inputs are known
  (`ImplicitStepper.predict`): the live loop does it between ticks, and a frame uses it only when it
  was made from the frame's very bits.
- the lid and lip contact is solved with the global step (forces of unknown size on the margin
  pairs, `sim.margin_contact.SolvedContact`), then v' = (x' - x) / h; the eyeball contact is a
  projection after it.

The matrix also carries a bending term along the lid and lip rows (`sim.margin_contact.
margin_bending`, K_b (x' - rest shape) with the rest shape turned with the jaw): a fine mesh's
pressed margin buckles into an alternating zig-zag without it; and the skin's own bending and its
guard against turning over (`sim.antifold`: the first in the matrix, the second on the right-hand
side, zero unless a triangle nears folding flat). RK2 has no such terms, so apart from them
(and from contact) the global equation at rest (x' = x = y) is exactly the force balance RK2 settles
to, and a settled pose is the same equilibrium; only the transient differs (implicit Euler damps fast
modes; the axial spring damping is left out, implicit Euler's own dissipation replaces it).

Substeps: accuracy, not stability, sets h: the slowest physically meaningful motion is the skin
swinging on its eq 9 tethers, omega_r = sqrt(tether / areal density) (~100 rad/s, and damped at
zeta ~ 0.6 by the mass damping); we take omega_r h <= OMEGA_H, which gives one substep per 60 Hz
frame. The price is a slower rise (benchmarks/sim_step.py measures it against RK2).
"""

from __future__ import annotations

import math

from typing import TYPE_CHECKING

import numba
import numpy as np

from sim.antifold import FoldGuard, _fold_forces, bending_of
from sim.antifold import warm_up as warm_up_folds
from sim.build import FaceModel
from sim.integrator import JawTurn, _eye_contact, row_deviation
from sim.margin_contact import (ROUNDS, SWEEPS, SolvedContact, _contact_force, _contact_resolve, _repair,
                                 solved_constraints, warm_up_solved)
from sim.numba_start import prepare_blas_check
from sim.supernodal import PrefactoredSolver, _sn_sweeps, _sym_sweeps

if TYPE_CHECKING:  # scipy is imported where a matrix is built: a stepper made from the face cache needs none
    import scipy.sparse as sp

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


def laplacian(n: int, springs: np.ndarray, w: np.ndarray) -> sp.csr_matrix:
    """Graph Laplacian (n, n) of the springs weighted by w: sum_s w_s (e_i - e_j)(e_i - e_j)^T."""
    import scipy.sparse as sp

    i, j = springs[:, 0].astype(np.int64), springs[:, 1].astype(np.int64)
    off = sp.coo_matrix((np.concatenate([-w, -w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                        shape=(n, n)).tocsr()
    diag = np.zeros(n)
    np.add.at(diag, i, w)
    np.add.at(diag, j, w)
    return (off + sp.diags(diag)).tocsr()


OMEGA_H = 2.0


def implicit_substeps(model: FaceModel, frame_dt: float) -> int:
    """Substeps per frame so that omega_r h <= OMEGA_H for the tether mode (module docstring)."""
    p = model.params
    omega_r = math.sqrt(p.tether / p.areal_density)
    return max(1, math.ceil(frame_dt * omega_r / OMEGA_H))


def spring_layout(springs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(runs, si3, sj3): the springs (S, 2) as `_pd_springs` reads them: each end's flat index
    3 x node as uint32 (no negative-index wraparound in the loops), and the bounds (R + 1,) of
    the runs of consecutive springs that share their first node."""
    springs = np.asarray(springs)
    if len(springs) and np.any(springs[:, 0] == springs[:, 1]):
        raise ValueError("a spring joins a node to itself")
    first = springs[:, 0].astype(np.int64)
    starts = np.flatnonzero(np.r_[True, first[1:] != first[:-1]]) if len(first) else np.zeros(0, dtype=np.int64)
    return (np.ascontiguousarray(np.r_[starts, len(first)], dtype=np.int64),
            np.ascontiguousarray(3 * first, dtype=np.uint32), np.ascontiguousarray(3 * springs[:, 1], dtype=np.uint32))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pd_springs(y, runs, si3, sj3, rest_len, k_low, kls, k_high, thr, out, work):  # type: ignore[no-untyped-def]
    """Adds sum_s k_h (e_j - e_i) d_s to out (the local step; see the module docstring); the
    springs laid out by `spring_layout`. Three passes over work (3, springs): gather the edge
    vectors, the per-spring math (no indexing, so the compiler vectorizes its square roots and
    divisions; error_model "numpy": a zero length gives inf instead of raising, which the step's
    guard catches), then the scatter in spring order, each run's shared first node kept in
    registers and stored once at the run's end (no spring of the run touches it otherwise, so it
    takes the very subtractions, in the same order: 76 -> 61 us for the scatter on the scanned
    head). Every value is the same expression as in one pass, so the same bits. Each spring's k_low
    is k_low[s] * kls (the skin's age: the product numpy made into an array before, the same bits)."""
    yf = y.reshape(-1)
    of = out.reshape(-1)
    ex = work[0]
    ey = work[1]
    ez = work[2]
    m = si3.shape[0]
    for s in range(m):
        i = si3[s]
        j = sj3[s]
        ex[s] = yf[j] - yf[i]
        ey[s] = yf[j + 1] - yf[i + 1]
        ez[s] = yf[j + 2] - yf[i + 2]
    for s in range(m):
        dx = ex[s]
        dy = ey[s]
        dz = ez[s]
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        stretch = r - rest_len[s]
        knee = thr * rest_len[s]
        kl = k_low[s] * kls
        soft = kl * stretch
        stiff = kl * knee + k_high[s] * (stretch - knee)
        t = soft if stretch <= knee else stiff
        scale = (k_high[s] * r - t) / r  # k_h * l_s / r: d_s = l_s u_s
        ex[s] = scale * dx
        ey[s] = scale * dy
        ez[s] = scale * dz
    for r in range(runs.shape[0] - 1):
        start = runs[r]
        stop = runs[r + 1]
        i = si3[start]
        o0 = of[i]
        o1 = of[i + 1]
        o2 = of[i + 2]
        for s in range(start, stop):
            j = sj3[s]
            fx = ex[s]
            fy = ey[s]
            fz = ez[s]
            of[j] += fx
            of[j + 1] += fy
            of[j + 2] += fz
            o0 -= fx
            o1 -= fy
            o2 -= fz
        of[i] = o0
        of[i + 1] = o1
        of[i + 2] = o2


@numba.njit(cache=True, nogil=True)
def _csr_times_flat(ptr, idx3, val, x, out):  # type: ignore[no-untyped-def]
    """out = A x for a CSR A and x (m, 3) given flat (3m,), each row summed in stored order from 0
    (as scipy does: the same bits): the row pointers and three times the column indices as uint32
    (`_flat_csr`), which spares the index arithmetic and the negative-index checks (0.13 -> 0.08
    ms on the scanned head's 114,578 entries of the margin bending, made every tick the jaw moves)."""
    for i in range(out.shape[0]):
        a0, a1, a2 = _row_times_flat(ptr, idx3, val, x, i)
        out[i, 0] = a0
        out[i, 1] = a1
        out[i, 2] = a2


@numba.njit(inline="always")
def _row_times_flat(ptr, idx3, val, x, i):  # type: ignore[no-untyped-def]
    """Row i of A x (`_csr_times_flat`'s arrays), summed from 0 in stored order, as three numbers."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for p in range(ptr[i], ptr[i + 1]):
        a = val[p]
        j = idx3[p]
        a0 += a * x[j]
        a1 += a * x[j + 1]
        a2 += a * x[j + 2]
    return a0, a1, a2


def _flat_csr(ptr: np.ndarray, idx: np.ndarray, val: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A CSR matrix's arrays as `_csr_times_flat` takes them (writeable copies: one compiled signature)."""
    if len(val) and (len(val) >= 2**32 or 3 * int(np.max(idx)) + 2 >= 2**32):
        raise ValueError("a CSR matrix too large for 32-bit indices")
    return (np.ascontiguousarray(ptr, dtype=np.uint32), np.ascontiguousarray(3 * np.asarray(idx, dtype=np.int64), dtype=np.uint32),
            np.array(val, dtype=np.float64))


@numba.njit(cache=True, nogil=True)
def _bend_turned(b0, b1, c, rot, slide, out):  # type: ignore[no-untyped-def]
    """out = the margin bending's rest side K_b s for the rest shape s turned with the jaw by the
    rotation `rot` and the slide `slide` (`ImplicitStepper.turn_basis`): K_b s is linear in them,
    row i = b0_i + rot b1_i + c_i slide, three values a row from K_b's products made once instead
    of its 114,578 entries (scanned head) a pose."""
    r, sl = _rotation_and_slide(rot, slide)
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = _turned_row(b0, b1, c, i, r, sl)


@numba.njit(inline="always")
def _rotation_and_slide(rot, slide):  # type: ignore[no-untyped-def]
    """The jaw's rotation (row-major) and slide as tuples of numbers: values, which the compiler keeps
    in registers over a loop that writes arrays (entries read from `rot` it must read again)."""
    return ((rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2], rot[2, 0], rot[2, 1], rot[2, 2]),
            (slide[0], slide[1], slide[2]))


@numba.njit(inline="always")
def _turned_row(b0, b1, c, i, r, sl):  # type: ignore[no-untyped-def]
    """Row i of the margin bending's rest side turned with the jaw, b0_i + rot b1_i + c_i slide."""
    e0, e1, e2 = b1[i, 0], b1[i, 1], b1[i, 2]
    ci = c[i]
    return (b0[i, 0] + (r[0] * e0 + r[1] * e1 + r[2] * e2) + ci * sl[0],
            b0[i, 1] + (r[3] * e0 + r[4] * e1 + r[5] * e2) + ci * sl[1],
            b0[i, 2] + (r[6] * e0 + r[7] * e1 + r[8] * e2) + ci * sl[2])


@numba.njit(cache=True, nogil=True)
def _bend_turned_add(b0, b1, c, rot, slide, ext, out, total):  # type: ignore[no-untyped-def]
    """`_bend_turned` into out, and total = ext + out in the same pass (`np.add` after it: the same
    bits, one pass and one call less)."""
    r, sl = _rotation_and_slide(rot, slide)
    for i in range(out.shape[0]):
        o0, o1, o2 = _turned_row(b0, b1, c, i, r, sl)
        out[i, 0] = o0
        out[i, 1] = o1
        out[i, 2] = o2
        total[i, 0] = ext[i, 0] + o0
        total[i, 1] = ext[i, 1] + o1
        total[i, 2] = ext[i, 2] + o2


@numba.njit(cache=True, nogil=True)
def _predict(x, v, h, runs, si3, sj3, rest_len, k_low, kls, k_high, thr, normal, kn, mass_h2, damp_h,  # type: ignore[no-untyped-def]
             c_idx, c_w, c_sg, c_dim, c_lam, f_t3, f_tri, f_frame, f_dm_inv, f_area, f_k, f_floor, f_dets, y, base, ext,
             summed, work, px, pv, keep):
    """The part of a substep's right-hand side that no input changes (ImplicitStepper.predict): the
    predicted positions y = x + h v, then base = M/h^2 y + C/h x + the springs' local step + the
    skin's guard against turning over (sim.antifold) + the normal support + the last contact
    forces. A substep's right-hand side is base + the frame's constant forces. summed: the frame's
    constant forces `ext` (muscles included) go into base where takes recorded before the muscles'
    responses summed them (`ImplicitStepper.frame`'s summed), so those takes keep their bits.
    runs, si3, sj3: the springs as `spring_layout` lays them out; work: (3, springs) scratch of
    `_pd_springs`; f_*: the fold guard's triangles (`sim.antifold._fold_forces`: f_t3 = 3 x
    f_tri as uint32, f_dets its (T,) scratch); keep: also px, pv = copies of x, v (what
    `ImplicitStepper.predict` remembers, made in the same pass over them)."""
    n = x.shape[0]
    for i in range(n):
        m = mass_h2[i]
        c = damp_h[i]
        for d in range(3):
            xi = x[i, d]
            vi = v[i, d]
            yi = vi * h + xi
            y[i, d] = yi
            base[i, d] = m * yi + ext[i, d] + c * xi if summed else m * yi + c * xi
            if keep:
                px[i, d] = xi
                pv[i, d] = vi
    _pd_springs(y, runs, si3, sj3, rest_len, k_low, kls, k_high, thr, base, work)
    _fold_forces(y, f_t3, f_tri, f_frame, f_dm_inv, f_area, f_k, f_floor, base, f_dets)
    for i in range(n):  # the support k_n n n^T: k_n (y - n (n . y)) on the right
        ny = (normal[i, 0] * y[i, 0] + normal[i, 2] * y[i, 2]) + normal[i, 1] * y[i, 1]
        k = kn[i]
        for d in range(3):
            base[i, d] += k * (y[i, d] - ny * normal[i, d])
    _contact_force(base, c_idx, c_w, c_sg, c_dim, c_lam)


@numba.njit(cache=True, nogil=True)
def _held_rhs(x, held, fh_ptr, fh_idx, fh_val, base, ext, free, perm_r, xh, ys, summed):  # type: ignore[no-untyped-def]
    """ys = base + ext minus the held nodes' coupling (they do not move within a frame), in the
    factors' row order: the right-hand side of the prefactored solve (`_sn_sweeps` then solves it
    in place, a kernel of its own: compiled inside this one its loops ran 20 % slower). Each free
    row's coupling is summed as `_csr_times_flat` sums it (from 0, in stored order) where it is
    used, not kept in an array of its own (the same bits)."""
    for k in range(held.shape[0]):
        i = held[k]
        for d in range(3):
            xh[k, d] = x[i, d]
    xf = xh.reshape(-1)
    for q in range(free.shape[0]):
        a0, a1, a2 = _row_times_flat(fh_ptr, fh_idx, fh_val, xf, q)
        i = free[q]
        r = perm_r[q]
        if summed:
            ys[r, 0] = base[i, 0] - a0
            ys[r, 1] = base[i, 1] - a1
            ys[r, 2] = base[i, 2] - a2
        else:
            ys[r, 0] = (base[i, 0] + ext[i, 0]) - a0
            ys[r, 1] = (base[i, 1] + ext[i, 1]) - a1
            ys[r, 2] = (base[i, 2] + ext[i, 2]) - a2


@numba.njit(cache=True, nogil=True)
def _held_rhs_turned(x, held, fh_ptr, fh_idx, fh_val, base, ext, b0, b1, c, rot, slide, free, perm_r, xh, ys):  # type: ignore[no-untyped-def]
    """`_held_rhs` (not summed) with ext + the margin bending's rest side turned with the jaw made
    row by row where it is used: each free row's ext + `_turned_row`, as `_bend_turned_add` made
    it into an array of its own before (the same bits; the held rows' are not needed): one pass over
    the rows and a call less at each new jaw pose (36 -> 29 us alone on the scanned head)."""
    for k in range(held.shape[0]):
        i = held[k]
        for d in range(3):
            xh[k, d] = x[i, d]
    xf = xh.reshape(-1)
    r9, sl = _rotation_and_slide(rot, slide)
    for q in range(free.shape[0]):
        a0, a1, a2 = _row_times_flat(fh_ptr, fh_idx, fh_val, xf, q)
        i = free[q]
        r = perm_r[q]
        o0, o1, o2 = _turned_row(b0, b1, c, i, r9, sl)
        ys[r, 0] = (base[i, 0] + (ext[i, 0] + o0)) - a0
        ys[r, 1] = (base[i, 1] + (ext[i, 1] + o1)) - a1
        ys[r, 2] = (base[i, 2] + (ext[i, 2] + o2)) - a2


@numba.njit(cache=True, nogil=True)
def _same_bits(a, b):  # type: ignore[no-untyped-def]
    """Whether two int64 arrays (views of float arrays) of the same size hold the very same bits:
    their differences ORed over the whole arrays, a loop the compiler vectorizes (no early exit:
    they are the same whenever a step uses its prediction; 16 -> 5 us for x or v of the scanned head)."""
    diff = 0
    for i in range(a.shape[0]):
        diff |= a[i] ^ b[i]
    return diff == 0


@numba.njit(cache=True, nogil=True)
def _unchanged(x, v, lam, w, idx, px, pv, plam, pw, pidx):  # type: ignore[no-untyped-def]
    """Whether a state (x, v and the contact's memory lam, w, idx; the floats as int64 views) holds
    the very bits of the one `_predict` (keep) and `_remember` kept (px, ...; the same sizes)."""
    return (_same_bits(x, px) and _same_bits(v, pv) and _same_bits(lam, plam) and _same_bits(w, pw)
            and _same_bits(idx.reshape(-1), pidx.reshape(-1)))


@numba.njit(cache=True, nogil=True)
def _remember(lam, w, idx, plam, pw, pidx):  # type: ignore[no-untyped-def]
    """plam, pw, pidx = copies of the contact's memory (`_unchanged`; x and v are kept by `_predict`)."""
    plam[...] = lam
    pw[...] = w
    pidx[...] = idx


@numba.njit(cache=True, nogil=True)
def _responses(resp, act, val, out):  # type: ignore[no-untyped-def]
    """out = sum over the active channels (in order) of each one's response times its activation:
    each value summed from 0 in the channels' order, four channels' responses a pass (contiguous
    passes, which the compiler vectorizes; each value takes its four terms one after the other, so
    the bits are those of a pass a channel; out is read and written a quarter as often: 49 -> 31
    us for the dial box's 15 channels on the scanned head), the one to three left in one pass."""
    o = out.reshape(-1)
    m = o.shape[0]
    k = 0
    while k + 4 <= act.shape[0]:
        r0, r1 = resp[act[k]].reshape(-1), resp[act[k + 1]].reshape(-1)
        r2, r3 = resp[act[k + 2]].reshape(-1), resp[act[k + 3]].reshape(-1)
        a0, a1, a2, a3 = val[k], val[k + 1], val[k + 2], val[k + 3]
        first = k == 0
        for p in range(m):
            s = 0.0 if first else o[p]
            s += r0[p] * a0
            s += r1[p] * a1
            s += r2[p] * a2
            s += r3[p] * a3
            o[p] = s
        k += 4
    left = act.shape[0] - k  # the last one to three channels in one pass too (not a pass each:
    first = k == 0  # each value still takes them one after the other; 42 -> 37 us for 15 channels)
    if left == 3:
        r0, r1, r2 = resp[act[k]].reshape(-1), resp[act[k + 1]].reshape(-1), resp[act[k + 2]].reshape(-1)
        a0, a1, a2 = val[k], val[k + 1], val[k + 2]
        for p in range(m):
            s = 0.0 if first else o[p]
            s += r0[p] * a0
            s += r1[p] * a1
            s += r2[p] * a2
            o[p] = s
    elif left == 2:
        r0, r1 = resp[act[k]].reshape(-1), resp[act[k + 1]].reshape(-1)
        a0, a1 = val[k], val[k + 1]
        for p in range(m):
            s = 0.0 if first else o[p]
            s += r0[p] * a0
            s += r1[p] * a1
            o[p] = s
    elif left == 1:
        r0 = resp[act[k]].reshape(-1)
        a0 = val[k]
        for p in range(m):
            s = 0.0 if first else o[p]
            s += r0[p] * a0
            o[p] = s
    elif first:
        o[:] = 0.0


@numba.njit(inline="always")
def _on_grid(rows, jaw):  # type: ignore[no-untyped-def]
    """The grid's opening k below `jaw` (0..1) and the fraction f past it, for a response grid of
    `rows` openings (`jaw_response`: row k is the response at k / (rows - 1))."""
    steps = rows - 1
    t = jaw * steps
    k = min(int(t), steps - 1)
    return k, t - k


@numba.njit(cache=True, nogil=True)
def _jaw_moves(jr, js, jaw_from, jaw_to, du, add, cell):  # type: ignore[no-untyped-def]
    """du (+= where add, else =) the jaw's response at `jaw_to` minus the one at `jaw_from` plus
    the slope `js` at the middle opening times the move, each linear between the grid's openings;
    one pass over the values laid flat (which the compiler vectorizes: 23 -> 10 us on the scanned
    head), each value receiving the three terms in that order (as three passes gave it). cell:
    where both openings lie between the same two of the grid's, the difference is taken as the
    fraction's change times the difference of those two rows (the same quantity, other bits: two
    rows read instead of four; the float32 responses', `ImplicitStepper.single_responses`)."""
    kt, ft = _on_grid(jr.shape[0], jaw_to)
    kf, ff = _on_grid(jr.shape[0], jaw_from)
    ks, fs = _on_grid(js.shape[0], 0.5 * (jaw_from + jaw_to))
    move = jaw_to - jaw_from
    o = du.reshape(-1)
    t0, t1 = jr[kt].reshape(-1), jr[kt + 1].reshape(-1)
    f0, f1 = jr[kf].reshape(-1), jr[kf + 1].reshape(-1)
    s0, s1 = js[ks].reshape(-1), js[ks + 1].reshape(-1)
    if cell and kt == kf:
        df = ft - ff
        for p in range(o.shape[0]):
            val = o[p] if add else 0.0
            val += df * (float(t1[p]) - float(t0[p]))
            a = float(s0[p])
            val += move * (a + fs * (float(s1[p]) - a))
            o[p] = val
        return
    for p in range(o.shape[0]):  # (float32 responses, `ImplicitStepper.single_responses`: in float64 as read)
        val = o[p] if add else 0.0
        a = float(t0[p])
        val += 1.0 * (a + ft * (float(t1[p]) - a))
        a = float(f0[p])
        val += -1.0 * (a + ff * (float(f1[p]) - a))
        a = float(s0[p])
        val += move * (a + fs * (float(s1[p]) - a))
        o[p] = val


@numba.njit(cache=True, nogil=True)
def _inputs(resp, act, act_val, jaw_resp, jaw_slope, jaw_from, jaw_to, du, cell):  # type: ignore[no-untyped-def]
    """du = what a frame's inputs add to each substep's solve (ImplicitStepper.frame): the muscles'
    responses, plus the jaw's move from `jaw_from` to `jaw_to` as the difference of its responses
    and the support's turn as its slope at the middle opening times the move (`jaw_response`; none
    when jaw_resp has no rows; cell: `_jaw_moves`'). Returns False when there is nothing to add
    (du not written)."""
    muscles = act.shape[0] > 0
    if muscles:
        _responses(resp, act, act_val, du)
    if jaw_resp.shape[0] > 0:
        _jaw_moves(jaw_resp, jaw_slope, jaw_from, jaw_to, du, muscles, cell)
        muscles = True
    return muscles


@numba.njit(cache=True, nogil=True)
def _advance(x, v, h, ys, du, muscles, free, perm_c, xf_old, c_idx, c_w, c_sg, c_dim, c_opp, c_row_ptr, c_row_v,  # type: ignore[no-untyped-def]
             c_lam, c_loc, c_green, c_gptr, c_gvert, c_gval, c_work, c_cand, c_schur, c_df, rounds, sweeps,
             eye_idx, eye_of, centres, radius, target, dev):
    """The end of a substep in place on x, v (ImplicitStepper.frame; the module docstring): x' =
    the solve ys (in the factors' order: perm_c reads it back) plus the inputs' du (`_inputs`,
    when `muscles`), the lid and lip contact (sim.margin_contact.SolvedContact), v = (x' - x) / h
    and the eyeball contact."""
    nf = free.shape[0]
    for q in range(nf):
        i = free[q]
        c = perm_c[q]
        for d in range(3):
            xf_old[q, d] = x[i, d]
            x[i, d] = ys[c, d] + du[q, d] if muscles else ys[c, d]
    if c_idx.shape[0]:
        _repair(x, c_idx, c_w, c_opp, c_row_ptr, c_row_v)
        for _ in range(rounds):  # again while the correction pushed other pairs into contact
            if not _contact_resolve(x, c_idx, c_w, c_sg, c_dim, c_lam, c_loc, c_green, c_gptr, c_gvert,
                                    c_gval, c_work, c_cand, c_schur, c_df, sweeps):
                break
    inv_h = 1.0 / h
    for q in range(nf):
        i = free[q]
        for d in range(3):
            v[i, d] = (x[i, d] - xf_old[q, d]) * inv_h
    _eye_contact(x, v, eye_idx, eye_of, centres, radius)
    if dev.shape[0]:  # the guard's measure on the free nodes (`ImplicitStepper.frame`'s check)
        dev[0] = _free_deviation(x, free, target)


@numba.njit(cache=True, nogil=True)
def _free_deviation(x, free, target):  # type: ignore[no-untyped-def]
    """max |x - target| over the free nodes' coordinates, or -1 if one is not finite
    (`sim.integrator._max_deviation` over those rows)."""
    worst = 0.0
    for q in range(free.shape[0]):
        worst = row_deviation(x, free[q], target, worst)
        if worst < 0.0:
            break
    return worst


def warm_up() -> None:
    """Compile (or load from numba's cache) this module's kernels on a tiny system."""
    import scipy.sparse as sp

    a = sp.csc_matrix(np.array([[2.0, -1.0], [-1.0, 2.0]]))
    PrefactoredSolver(a).solve(np.ones((2, 3)), np.zeros((2, 3)))
    warm_up_solved()
    warm_up_folds()
    x = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0], [0.5, 1.0, 0.0]])
    stepper = ImplicitStepper.__new__(ImplicitStepper)
    one = np.ones(3)
    springs = np.array([[0, 1], [1, 2]], dtype=np.int32)
    prep = dict(free=np.array([1, 2], dtype=np.int64), held=np.array([0], dtype=np.int64), mass_h2=one.copy(),
                damp_h=one.copy(), kn=one.copy(), h=np.array(0.01))
    prep.update(_sparse("fh", sp.csr_matrix(np.ones((2, 1)))))
    prep.update(_sparse("bend", sp.csr_matrix((3, 3))))
    prep.update(_fold_arrays(FoldGuard(x, np.array([[0, 1, 2]]), springs, one[:2])))
    prep.update({"lu_" + k: val for k, val in PrefactoredSolver(sp.csc_matrix(np.array([[3.0, -1.0], [-1.0, 3.0]]))).arrays.items()})
    cons = dict(idx=np.array([[1, 0, 2]]), w=np.array([0.5]), sg=np.array([[1.0, 0.0, 1.0, 1.0]]),
                dim=np.array([1]), opp=np.array([0]), row_ptr=np.array([0, 2]), row_v=np.array([0, 2]))
    contact = SolvedContact(cons, np.arange(3), 3, lambda b, out: np.copyto(out, b))
    prep.update({"c_" + k: val for k, val in contact.arrays().items()})
    prep["resp"] = np.zeros((1, 2, 3))
    stepper._setup(x, prep)
    _csr_times_flat(*_flat_csr(*_sparse("w", sp.csr_matrix(np.ones((3, 3)))).values()), x.reshape(-1), np.zeros((3, 3)))
    _bend_turned(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), np.eye(3), np.zeros(3), np.zeros((3, 3)))
    _bend_turned_add(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), np.eye(3), np.zeros(3), np.zeros((3, 3)),
                     np.zeros((3, 3)), np.zeros((3, 3)))
    free, held, perm_r = stepper._index[:3]
    _held_rhs_turned(x, held, *stepper._fh, np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)),
                     np.zeros(3), np.eye(3), np.zeros(3), free, perm_r, np.zeros((1, 3)), np.zeros((2, 3)))
    eyes = (np.array([1], dtype=np.int64), np.array([0], dtype=np.int64), np.array([[0.0, 0.0, 5.0]]), 1.0)
    v, spring_arrays = np.zeros_like(x), (springs, np.ones(2), np.ones(2), np.ones(2), 0.1)
    stepper.predict(x, v, np.zeros_like(x), spring_arrays, np.zeros_like(x), None, "warm-up")  # between ticks
    active = (np.array([0], dtype=np.int64), np.array([0.5]))
    stepper.frame(x, v, 1, np.zeros_like(x), spring_arrays, np.zeros_like(x), eyes, key="warm-up", active=active)
    stepper.jaw_resp, stepper.jaw_slope = np.zeros((3, 2, 3)), np.zeros((3, 2, 3))
    stepper.jaw_response(np.zeros_like(x), x, x[:1], stepper.jaw_resp[1])
    stepper.frame(x, v, 1, np.zeros_like(x), spring_arrays, np.zeros_like(x), eyes, active=active, jaw=(0.2, 0.7))
    stepper.frame(x, v, 1, np.zeros_like(x), spring_arrays, np.zeros_like(x), eyes)
    stepper.single_responses = False  # (the float64 responses of takes recorded before)
    stepper.frame(x, v, 1, np.zeros_like(x), spring_arrays, np.zeros_like(x), eyes, active=active, jaw=(0.2, 0.7))
    stepper.frame(x, v, 1, np.zeros_like(x), spring_arrays, np.zeros_like(x), eyes, active=active)


def _sparse(name: str, m: sp.spmatrix) -> dict[str, np.ndarray]:
    """A CSR matrix as three arrays (name_ptr int64, name_idx int64, name_val)."""
    import scipy.sparse as sp

    m = sp.csr_matrix(m)
    return {name + "_ptr": m.indptr.astype(np.int64), name + "_idx": m.indices.astype(np.int64),
            name + "_val": np.asarray(m.data, dtype=np.float64)}


def _fold_arrays(guard: FoldGuard) -> dict[str, np.ndarray]:
    """A FoldGuard's per-triangle data as prepared arrays (fold_*)."""
    return dict(fold_tri=np.ascontiguousarray(guard.tri, dtype=np.int64), fold_frame=guard.frame,
                fold_dm_inv=guard.dm_inv, fold_area=np.asarray(guard.area, dtype=np.float64),
                fold_k=np.asarray(guard.k, dtype=np.float64), fold_floor=np.array(float(guard.floor)))


def muscle_responses(solver: PrefactoredSolver, free: np.ndarray, n: int, fields: object,
                     channels: np.ndarray) -> np.ndarray:
    """(C, free nodes, 3): the step's response to each of `channels` (columns of the (3N, C) CSR
    `fields`, with indptr, indices and data: a muscle's force at full activation), A^-1 of its
    force on the free nodes; zero for the other columns. The step is linear in the muscles'
    forces, so a frame adds the active channels' responses times their activations to the solve
    of everything else (which the live loop computes before the inputs are known,
    `ImplicitStepper.predict`) instead of solving the muscles' forces again each frame."""
    indptr = np.asarray(fields.indptr)  # type: ignore[attr-defined]
    indices = np.asarray(fields.indices)  # type: ignore[attr-defined]
    data = np.asarray(fields.data, dtype=np.float64)  # type: ignore[attr-defined]
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    resp = np.zeros((int(fields.shape[1]), len(free), 3))  # type: ignore[attr-defined]
    for c in channels:
        f = np.zeros(3 * n)
        on = indices == c
        np.add.at(f, rows[on], data[on])
        f3 = np.ascontiguousarray(f.reshape(n, 3)[free])
        if f3.any():
            solver.solve(f3, resp[int(c)])
    return resp


def gaze_responses(solver: PrefactoredSolver, free: np.ndarray, model: FaceModel) -> np.ndarray:
    """(3 N_BASIS, free nodes, 3): the step's response to each fixed field of the lids' pull by the
    turning eyes (`sim.gaze_lids.basis_fields`), first with the lids alike (takes recorded before
    the header's "lid coupling"), then with the upper and lower lids apart (`lid_couplings`), then
    apart with the tissue round the globe carried by the turning eye (`sim.gaze_lids.tissue_fields`,
    the rig's `gaze`: takes recorded before the header's "gaze tissue" replay without it; a face
    without it has the second set again); a frame adds one set times the gaze's coefficients after
    the muscles' responses, as it adds those."""
    from sim.gaze_lids import N_BASIS, basis_fields, lid_couplings, tissue_fields

    out = np.zeros((3 * N_BASIS, len(free), 3))
    tissue = tissue_fields(model)
    for j, (idx, eye, gain, pitch_gain) in enumerate(lid_couplings(model)):
        for k, f in enumerate(basis_fields(np.asarray(model.rest), idx, eye, gain, model.mesh.eye_centers, pitch_gain)):
            f3 = np.ascontiguousarray(f[free])
            if f3.any():
                solver.solve(f3, out[j * N_BASIS + k])
            if j == 1:
                if tissue is None or not tissue[k].any():
                    out[2 * N_BASIS + k] = out[N_BASIS + k]
                else:
                    solver.solve(np.ascontiguousarray((f + tissue[k])[free]), out[2 * N_BASIS + k])
    return out


def prepare(model: FaceModel, h: float) -> dict[str, np.ndarray]:
    """Everything an ImplicitStepper for `model` at substep h is made of, as arrays (the slow part
    of making one: building and factoring the matrix, the contact's Green's function). The face
    cache keeps them (`sim.prepared`): a stepper made from them steps to the same bits."""
    import scipy.sparse as sp

    n = model.n_vertices
    springs = np.asarray(model.spring_indices)
    held = np.asarray(model.held)
    free, held_i = np.flatnonzero(~held), np.flatnonzero(held)
    mass_h2 = np.asarray(model.mass) / h**2
    damp_h = np.asarray(model.damping) / h
    kn = np.asarray(model.support_stiffness)
    bend = bending_of(model)  # the lid and lip rows' and the skin's own bending (sim.antifold), in the matrix
    a = (laplacian(n, springs, np.asarray(model.spring_k_high)) + bend
         + sp.diags(mass_h2 + damp_h + np.asarray(model.rest_stiffness) + kn)).tocsr()
    solver = PrefactoredSolver(a[free][:, free])
    prep = dict(free=free.astype(np.int64), held=held_i.astype(np.int64), mass_h2=mass_h2, damp_h=damp_h,
                kn=np.array(kn, dtype=np.float64), h=np.array(float(h)))
    prep.update(_sparse("fh", a[free][:, held_i]))
    prep.update(_sparse("bend", bend))
    # the skin's thickness against folding over (sim.antifold), on the predicted positions
    prep.update(_fold_arrays(FoldGuard(model.rest, model.triangles, springs, np.asarray(model.spring_k_high))))
    prep.update({"lu_" + k: val for k, val in solver.arrays.items()})
    muscles = np.flatnonzero([c.kind == "muscle" for c in model.channels])
    prep["resp"] = np.concatenate([muscle_responses(solver, free, n, model.muscle_matrix, muscles),
                                   gaze_responses(solver, free, model)])
    cons = solved_constraints(model.mesh, model.rest)  # the lid and lip contact (sim.margin_contact)
    if len(cons["idx"]):
        contact = SolvedContact(cons, free, n, solver.solve)
        prep.update({"c_" + k: val for k, val in contact.arrays().items()})
    return prep


_SINGLE: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def single_of(a: np.ndarray) -> np.ndarray:
    """The float32 copy of `a`, an array nothing writes to (the prepared responses, the jaw's grid:
    shared by the simulators of a face), made once per array in a process: a show's simulator and
    its kernel warm-up's share it (~20 MB cast at each start of the scanned head). The copy is
    read only."""
    hit = _SINGLE.get(id(a))
    if hit is not None and hit[0] is a:
        return hit[1]
    out = np.ascontiguousarray(a, dtype=np.float32)
    if len(_SINGLE) >= 8:
        _SINGLE.clear()
    _SINGLE[id(a)] = (a, out)
    return out


class ImplicitStepper:
    """Runs the substeps of one frame for a Simulator (method "implicit"). `prepared`: the arrays
    of `prepare(model, h)` made before (`sim.prepared`: this process's or the face cache's), else
    they are made here. The stepper never writes to them."""

    def __init__(self, model: FaceModel, h: float, prepared: dict[str, np.ndarray] | None = None) -> None:
        self._setup(np.asarray(model.rest), prepare(model, h) if prepared is None else prepared)

    def _setup(self, rest: np.ndarray, prep: dict[str, np.ndarray]) -> None:
        self.prepared = prep
        n = len(rest)
        self.h = float(prep["h"])
        self.free, self.held = prep["free"], prep["held"]
        self.mass_h2, self.damp_h, self.kn = prep["mass_h2"], prep["damp_h"], prep["kn"]
        self.rest = rest
        self._fh = _flat_csr(prep["fh_ptr"], prep["fh_idx"], prep["fh_val"])
        self._bend = (prep["bend_ptr"], prep["bend_idx"], prep["bend_val"])
        self._bend_flat = _flat_csr(*self._bend)
        tri = prep["fold_tri"]  # (the flat indices and the dets' scratch: `sim.antifold._fold_forces`)
        self._folds = (np.ascontiguousarray(3 * tri, dtype=np.uint32), tri, prep["fold_frame"], prep["fold_dm_inv"],
                       prep["fold_area"], prep["fold_k"], float(prep["fold_floor"]), np.zeros(len(tri)))
        self.solver = PrefactoredSolver(arrays={k: prep["lu_" + k] for k in PrefactoredSolver.KEYS})
        #: a substep's solve from the symmetric factor alone (`sim.supernodal._sym_sweeps`: L and D,
        #: U's values left unread); False: from L and U (`_sn_sweeps`), as takes recorded before
        #: (sim.Simulator.symmetric_solve). The prepared responses are the LU solve's either way.
        self.symmetric_solve = self.solver.symmetric
        if "c_idx" in prep:
            self.margins: SolvedContact | None = SolvedContact.from_arrays(
                {k: prep["c_" + k] for k in SolvedContact.KEYS})
        else:
            self.margins = None
        none = SolvedContact.from_arrays(dict(idx=np.zeros((0, 3)), w=np.zeros(0), sg=np.zeros((0, 4)), dim=np.zeros(0),
                                              opp=np.zeros(0), row_ptr=np.zeros(1), row_v=np.zeros(0), loc=np.zeros(n),
                                              green=np.zeros((0, 0)), gptr=np.zeros(1), gvert=np.zeros(0), gval=np.zeros(0)))
        self._contact = self.margins if self.margins is not None else none
        self._shape: np.ndarray | JawTurn | None = None
        self._turn_b = (np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n))  # `turn_basis`
        self._bend_rhs = np.zeros((n, 3))
        self._ext = np.zeros((n, 3))
        self._bent: tuple[object, object] = (None, None)  # (ext, key) `_ext` was summed for by `predict`
        nf, nh = len(self.free), len(self.held)
        # the node lists and the factors' permutations as the kernels index with them: unsigned
        # (never negative), so no index needs a check for wrapping around (the same values)
        unsigned = np.uint64
        self._index = (np.ascontiguousarray(self.free, dtype=np.int64).view(unsigned),
                       np.ascontiguousarray(self.held, dtype=np.int64).view(unsigned),
                       np.ascontiguousarray(self.solver.perm_r, dtype=np.int64).view(unsigned),
                       np.ascontiguousarray(self.solver.perm_c, dtype=np.int64).view(unsigned))
        # y, base, the held nodes' x, the solve's ys, the free nodes' x before a substep, du
        self._buf = (np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((nh, 3)), np.zeros((nf, 3)), np.zeros((nf, 3)),
                     np.zeros((nf, 3)))
        self._springs_scratch = np.zeros((3, 0))
        self._layout_of: np.ndarray | None = None  # the springs array `_spring_runs` was laid out from
        self._spring_runs = spring_layout(np.zeros((0, 2), dtype=np.int64))
        self._resp64 = prep["resp"]  # each muscle channel's response (`muscle_responses`; `_resp`)
        #: the jaw's responses at evenly spaced openings (`jaw_response`), set by the Simulator
        self.jaw_resp = np.zeros((0, nf, 3))
        #: and the slope of the normal support's response to the opening there (`frame`'s jaw)
        self.jaw_slope = np.zeros((0, nf, 3))
        #: a frame reads the inputs' responses (the muscles', the gaze's, the jaw's and its slope)
        #: rounded to float32 (`_single`: half the bytes from memory a tick, the sums still in
        #: float64), a jaw's move within a grid step from two of its rows (`_jaw_moves`' cell);
        #: other bits: the take header's "responses", sim.Simulator.single_responses. False: the
        #: float64 responses and four rows, as takes recorded before
        self.single_responses = True
        self._resp32 = single_of(self._resp64)  # (the shared arrays' copy: once per process)
        self._jaw32: tuple[object, object, np.ndarray, np.ndarray] = (None, None, np.zeros((0, nf, 3), np.float32),
                                                                     np.zeros((0, nf, 3), np.float32))
        self._no_jaw32 = np.zeros((0, nf, 3), dtype=np.float32)
        self._no_act = (np.zeros(0, dtype=np.int64), np.zeros(0))
        self._dev, self._no_dev = np.zeros(1), np.zeros(0)  # `frame`'s check
        #: the last `frame`'s max |x - check| over the free nodes (-1: not finite), None without a check
        self.last_deviation: float | None = None
        self._no_jaw = np.zeros((0, nf, 3))
        # what the last `predict` was made from: its key, x, v and the contact's memory
        self._predicted: object = None
        #: whether the last `frame` found its first substep's solve made ahead
        self.last_predicted = False
        c = self._contact
        self._px, self._pv = np.zeros((n, 3)), np.zeros((n, 3))
        self._plam, self._pw, self._pidx = np.zeros_like(c.lam), np.zeros_like(c.w), np.zeros_like(c.idx)
        bits = np.int64  # their bits as `_unchanged` compares them (views: they follow the copies)
        self._kept_bits = (self._px.reshape(-1).view(bits), self._pv.reshape(-1).view(bits), self._plam.view(bits),
                           self._pw.view(bits), self._pidx)
        self._contact_bits = (c.lam.view(bits), c.w.view(bits), c.idx)  # (the contact's arrays are never replaced)
        self._state_bits: tuple = (None, None, ())  # type: ignore[type-arg]  # x, v and their views, made once for them
        # the contact's arrays as `_predict` and `_advance` take them, gathered once (not 20 lookups a tick)
        self._predict_c = (c.idx, c.w, c.sg, c.dim, c.lam)
        self._advance_c = (c.idx, c.w, c.sg, c.dim, c.opp, c.row_ptr, c.row_v, c.lam, c.loc, c.green, c.gptr, c.gvert,
                           c.gval, c._work, c._cand, c._schur, c._df, ROUNDS, SWEEPS)

    def turn_basis(self, weight: np.ndarray, pivot: np.ndarray) -> None:
        """Make the products that give the margin bending's rest side for any turn of the jaw
        (`_bend_turned`, a `frame` or `predict` given a JawTurn as its shape): the rest shape
        turned by R and slid by s is s_i = r_i + w_i ((R - I)(r_i - p) + s) for the jaw's weights
        w and pivot p, so K_b s = (K_b r - K_b W D) + (K_b W D) R^T + (K_b w) s^T with D the rows
        r_i - p. The same values as the product K_b s up to rounding (a take's header says which
        it was recorded with: sim.Simulator.bending_turned)."""
        n = len(self.rest)
        weight = np.asarray(weight, dtype=np.float64)
        wd = np.ascontiguousarray(weight[:, None] * (np.asarray(self.rest, dtype=np.float64) - np.asarray(pivot)))
        kr, kwd, kw = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        if len(self._bend[2]):
            _csr_times_flat(*self._bend_flat, np.ascontiguousarray(self.rest, dtype=np.float64).reshape(-1), kr)
            _csr_times_flat(*self._bend_flat, wd.reshape(-1), kwd)
            _csr_times_flat(*self._bend_flat, np.ascontiguousarray(np.repeat(weight[:, None], 3, axis=1)).reshape(-1), kw)
        self._turn_b = (kr - kwd, kwd, np.ascontiguousarray(kw[:, 0]))

    def _with_bending(self, ext: np.ndarray, shape: np.ndarray | JawTurn | None, key: object = None) -> np.ndarray:
        """ext plus the margin bending term's rest side (its shape changes with the jaw; a JawTurn:
        the rest shape turned by it, made by `_bend_turned` from `turn_basis`'s products). key:
        `predict`'s name for ext and shape (its ext_key): the sum made for the same key, ext and
        shape is kept (a jaw at rest's every tick, the age moving or not: 18k values added again,
        12 us)."""
        if not len(self._bend[2]):
            return ext
        shape = self.rest if shape is None else shape
        if key is not None and ext is self._bent[0] and shape is self._shape and key == self._bent[1]:
            return self._ext
        self._bent = (None, None)
        if shape is not self._shape:
            self._shape = shape
            if isinstance(shape, JawTurn):
                if ext.shape == self._ext.shape and ext.dtype == np.float64 and ext.flags.c_contiguous:
                    _bend_turned_add(*self._turn_b, shape.rot, shape.slide, ext, self._bend_rhs, self._ext)
                    self._bent = (ext, key)
                    return self._ext
                _bend_turned(*self._turn_b, shape.rot, shape.slide, self._bend_rhs)
            else:
                _csr_times_flat(*self._bend_flat, np.ascontiguousarray(shape, dtype=np.float64).reshape(-1),
                                self._bend_rhs)
        np.add(ext, self._bend_rhs, out=self._ext)
        self._bent = (ext, key)
        return self._ext

    def predict(self, x: np.ndarray, v: np.ndarray, ext: np.ndarray, springs: tuple,  # type: ignore[type-arg]
                normal: np.ndarray, shape: np.ndarray | JawTurn | None, key: object, ext_key: object = None) -> None:
        """Solve now the first substep for everything but the muscles (`_predict`, ext: the frame's
        constant forces without them, the held nodes), for a `frame` that follows with the same x,
        v, contact memory and `key` (the caller's name for ext, shape, the springs' constants and
        the normals: the jaw's pose and the skin's age; ext_key: its name for ext and shape alone,
        under which their sum with the margin bending is kept, `_with_bending`). The live loop runs
        it between ticks, so a tick that takes an input only adds the muscles' responses and solves
        the contact. A frame given anything else computes it again: the same bits either way."""
        turn = None
        if (isinstance(shape, JawTurn) and len(self._bend[2]) and ext.shape == self._ext.shape
                and ext.dtype == np.float64 and ext.flags.c_contiguous):
            turn = shape  # the bending's rest side made where it is used (`_held_rhs_turned`)
            self._shape = None  # (`_with_bending`'s sum not made: a frame that needs it makes it)
        else:
            ext = self._with_bending(ext, shape, ext_key)
        self._predicted = None
        self._solve_free(x, v, ext, springs, normal, False, keep=x.shape == self._px.shape, turn=turn)
        c = self._contact
        _remember(c.lam, c.w, c.idx, self._plam, self._pw, self._pidx)
        self._predicted = key

    def _layout(self, springs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`spring_layout` of the springs array given, made once for it (the Simulator passes the same array)."""
        if self._layout_of is not springs:
            self._spring_runs = spring_layout(springs)
            self._layout_of = springs
        return self._spring_runs

    def _spring_work(self, springs: int) -> np.ndarray:
        """The (3, springs) scratch of the springs' local step (`_pd_springs`), made once."""
        if self._springs_scratch.shape[1] != springs:
            self._springs_scratch = np.zeros((3, springs))
        return self._springs_scratch

    def _solve_free(self, x: np.ndarray, v: np.ndarray, ext: np.ndarray, springs: tuple,  # type: ignore[type-arg]
                    normal: np.ndarray, summed: bool, keep: bool = False, turn: JawTurn | None = None) -> None:
        """ys = the solve of a substep's right-hand side without the inputs' responses: `_predict`,
        the held nodes' coupling (`_held_rhs`) and the prefactored solve (three kernels); keep:
        x and v are copied for `_is_predicted` on the way; turn: ext is without the margin
        bending's rest side, which is made for this turn of the jaw (`_held_rhs_turned`)."""
        idx, rest_len, k_low, k_high, thr = springs[:5]
        kls = float(springs[5]) if len(springs) > 5 else 1.0  # k_low's scale (the skin's age)
        y, base, xh, ys = self._buf[:4]
        _predict(x, v, self.h, *self._layout(idx), rest_len, k_low, kls, k_high, thr, normal, self.kn, self.mass_h2, self.damp_h,
                 *self._predict_c, *self._folds, y, base, ext, summed,
                 self._spring_work(len(idx)), self._px, self._pv, keep)
        free, held, perm_r = self._index[:3]
        if turn is not None:
            _held_rhs_turned(x, held, *self._fh, base, ext, *self._turn_b, turn.rot, turn.slide, free, perm_r, xh, ys)
        else:
            _held_rhs(x, held, *self._fh, base, ext, free, perm_r, xh, ys, summed)
        if self.symmetric_solve:
            _sym_sweeps(ys, *self.solver.sym_factors, self.solver.work)
        else:
            _sn_sweeps(ys, *self.solver.factors, self.solver.work)

    def jaw_response(self, ext: np.ndarray, shape: np.ndarray | None, held_at: np.ndarray | None,
                     out: np.ndarray) -> None:
        """out (free nodes, 3) = A^-1 of the right-hand side's terms that the jaw's pose alone sets:
        `ext` (the tether's and the support's constant forces at that pose), the margin bending's
        rest side of `shape` and the held nodes' coupling with them at `held_at` (held nodes, 3).
        The step is linear in them, so a jaw moved between two poses adds the difference of their
        responses to the solve of everything else (`frame`'s jaw). shape, held_at None: ext alone."""
        n = len(self.rest)
        b = np.array(ext, dtype=np.float64)
        if shape is not None and len(self._bend[2]):
            bend = np.zeros((n, 3))
            _csr_times_flat(*self._bend_flat, np.ascontiguousarray(shape, dtype=np.float64).reshape(-1), bend)
            b += bend
        held_term = np.zeros((len(self.free), 3))
        if held_at is not None:
            _csr_times_flat(*self._fh, np.ascontiguousarray(held_at, dtype=np.float64).reshape(-1), held_term)
        self.solver.solve(np.ascontiguousarray(b[self.free] - held_term), out)

    @property
    def _resp(self) -> np.ndarray:
        """Each input's response (channels, free nodes, 3), float64. Set anew: its float32 copy
        (`single_responses`) is made again; changed in place (a fit's gains, `sim.fit`), call
        `responses_changed` before the next frame."""
        return self._resp64

    @_resp.setter
    def _resp(self, resp: np.ndarray) -> None:
        self._resp64 = resp
        self.responses_changed()

    def responses_changed(self) -> None:
        """The float32 copy of the responses made again from `_resp` (changed in place)."""
        self._resp32 = np.ascontiguousarray(self._resp64, dtype=np.float32)

    def _single(self, jaw: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inputs' responses as a frame reads them with `single_responses`: float32 copies of
        the muscles' (made with the stepper) and of the jaw's grid and slope (made when the
        Simulator sets them); with jaw False, no jaw rows."""
        if not jaw:
            return self._resp32, self._no_jaw32, self._no_jaw32
        made_r, made_s, r32, s32 = self._jaw32
        if made_r is not self.jaw_resp or made_s is not self.jaw_slope:
            r32, s32 = single_of(self.jaw_resp), single_of(self.jaw_slope)
            self._jaw32 = (self.jaw_resp, self.jaw_slope, r32, s32)
        return self._resp32, r32, s32

    def _is_predicted(self, x: np.ndarray, v: np.ndarray, key: object) -> bool:
        """True when the last `predict` was made from these very bits and key."""
        if self._predicted is None or key != self._predicted:
            return False
        if x.shape != self._px.shape or v.shape != self._pv.shape or not (x.flags.c_contiguous and v.flags.c_contiguous):
            return False
        c = self._contact
        if c.lam.shape != self._plam.shape or c.idx.shape != self._pidx.shape:
            return False
        sx, sv, views = self._state_bits
        if sx is not x or sv is not v:  # (the live loop steps the same state's arrays every tick)
            bits = np.int64
            views = (x.reshape(-1).view(bits), v.reshape(-1).view(bits))
            self._state_bits = (x, v, views)
        return bool(_unchanged(*views, *self._contact_bits, *self._kept_bits))

    def frame(self, x: np.ndarray, v: np.ndarray, n_sub: int, ext: np.ndarray, springs: tuple,  # type: ignore[type-arg]
              normal: np.ndarray, eyes: tuple, shape: np.ndarray | JawTurn | None = None,  # type: ignore[type-arg]
              key: object = None, active: tuple[np.ndarray, np.ndarray] | None = None, summed: bool = False,
              jaw: tuple[float, float] | None = None, check: np.ndarray | None = None) -> None:
        """n_sub substeps in place. ext: the frame-constant forces (gravity, the target terms of the
        tether and of the normal support, and muscles not given by `active`); springs: (indices,
        rest lengths, k_low, k_high, threshold[, a scale of k_low, 1 if left out]) as the kernel takes them; normal (N,3): the
        support's normals this frame. The support k_n n n^T enters like a spring: k_n I in the
        matrix, k_n (y - n (n . y)) on the right. eyes: (vertices, their eye, eye centres, radius)
        of the eyeball contact applied after each substep; shape (N,3): the rest shape of the margin
        bending term this frame (turned with the jaw, or the JawTurn that turns it; None: the
        model's rest); key: as `predict`'s (None: never use a prediction); active: (channels, activations) whose responses
        (`muscle_responses`) are added; summed: ext holds every muscle and is summed in the order of
        the step before the responses, for the takes recorded with it (no prediction, no `active`);
        jaw: (from, to) openings: ext, shape, normal and the held nodes are the jaw's pose at `from`,
        and the difference of the jaw's responses (`jaw_resp`, `jaw_response`) and the support's
        slope (`jaw_slope`) move it to `to`. check: a target (N,3) to measure the free nodes
        against after the last substep, max |x - target| (or -1: a coordinate not finite) into
        `last_deviation` for the caller's guard (measured while x is in the caches)."""
        predicted = key is not None and not summed and self._is_predicted(x, v, key)
        self._predicted = None  # a prediction serves one frame
        self.last_predicted = predicted
        if n_sub > 1 or not predicted:  # (a prediction holds the first substep's)
            ext = self._with_bending(ext, shape)
        act, act_val = self._no_act if active is None else active
        du = self._buf[5]
        if self.single_responses:
            resp, jaw_resp, jaw_slope = self._single(jaw is not None)
        else:
            resp = self._resp
            jaw_resp, jaw_slope = (self.jaw_resp, self.jaw_slope) if jaw is not None else (self._no_jaw, self._no_jaw)
        jaw_from, jaw_to = jaw if jaw is not None else (0.0, 0.0)
        muscles = _inputs(resp, act, act_val, jaw_resp, jaw_slope, jaw_from, jaw_to, du, self.single_responses)
        self.last_deviation = None
        for sub in range(n_sub):
            if sub > 0 or not predicted:
                self._solve_free(x, v, ext, springs, normal, summed)
            last = check is not None and sub == n_sub - 1
            _advance(x, v, self.h, self._buf[3], du, muscles, self._index[0], self._index[3], self._buf[4],
                     *self._advance_c, *eyes, check if last else x, self._dev if last else self._no_dev)
        if check is not None and n_sub > 0:
            self.last_deviation = float(self._dev[0])
