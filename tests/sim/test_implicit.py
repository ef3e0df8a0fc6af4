"""The implicit (projective-dynamics) integrator for big meshes: same equilibria as RK2, exact
prefactored solves, rest stays rest, determinism, and the automatic choice."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from sim.build import FaceModel, SkinParams, compile_model
from sim.implicit import PrefactoredSolver, laplacian
from sim.integrator import RK2_WORK_LIMIT, Simulator
from sim.model import FaceRig
from sim.state import FaceControl


def _settled(model: FaceModel, control: FaceControl, method: str) -> tuple[Simulator, np.ndarray]:
    sim = Simulator(model, wrinkles=False, method=method)
    state = model.rest_state()
    sim.settle(state, control, max_seconds=5.0)
    return sim, state.positions


def test_prefactored_solve_matches_a_direct_solve(synth_model: FaceModel) -> None:
    n = synth_model.n_vertices
    a = laplacian(n, np.asarray(synth_model.spring_indices), np.asarray(synth_model.spring_k_high))
    a = (a + sp.diags(np.asarray(synth_model.mass) * 3600.0)).tocsc()
    b = np.random.default_rng(3).normal(size=(n, 3))
    out = np.zeros_like(b)
    PrefactoredSolver(a).solve(b, out)
    assert np.allclose(out, spsolve(a, b), rtol=1e-10, atol=1e-12)


def _forward_sweep(lu: object, low: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """L^-1 Pr b by the plain column-by-column forward sweep (L has a unit diagonal)."""
    y = np.zeros_like(b)
    y[lu.perm_r] = b  # type: ignore[attr-defined]
    for j in range(low.shape[0]):
        for p in range(low.indptr[j], low.indptr[j + 1]):
            if low.indices[p] > j:
                y[low.indices[p]] -= low.data[p] * y[j]
    return y


def _column_sweeps(lu: object, b: np.ndarray) -> np.ndarray:
    """Pc U^-1 L^-1 Pr b by the plain column-by-column sweeps (each entry of L and U in turn)."""
    low, up = sp.csc_matrix(lu.L), sp.csc_matrix(lu.U)  # type: ignore[attr-defined]
    n = low.shape[0]
    y = _forward_sweep(lu, low, b)
    for j in range(n - 1, -1, -1):
        rows, vals = up.indices[up.indptr[j]:up.indptr[j + 1]], up.data[up.indptr[j]:up.indptr[j + 1]]
        y[j] = y[j] / vals[rows == j][0]
        for r, a in zip(rows, vals):
            if r < j:
                y[r] -= a * y[j]
    return y[lu.perm_c]  # type: ignore[attr-defined]


def test_the_supernodal_solve_gives_the_bits_of_the_column_sweeps(synth_model: FaceModel) -> None:
    """The solve is laid out by supernodes (sim.supernodal) for speed, but every value takes its
    subtractions in the column sweeps' order: a take recorded with either replays bit-exactly."""
    from scipy.sparse.linalg import splu

    n = synth_model.n_vertices
    a = laplacian(n, np.asarray(synth_model.spring_indices), np.asarray(synth_model.spring_k_high))
    a = (a @ a + a + sp.diags(np.asarray(synth_model.mass) * 3600.0)).tocsc()  # a wider stencil: wide runs
    solver = PrefactoredSolver(a)
    widths = np.diff(solver.arrays["sn_ptr"])
    assert widths.max() >= 8 and (widths == 1).any()  # both kinds of run are exercised
    lu = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    rng = np.random.default_rng(11)
    for _ in range(3):
        b = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, size=(n, 1))
        out = np.zeros_like(b)
        solver.solve(b, out)
        assert out.tobytes() == _column_sweeps(lu, b).tobytes()


def test_the_rk2_equilibrium_is_a_fixed_point_of_the_implicit_step(synth_rig: FaceRig) -> None:
    """Both integrators balance the same forces, but for the implicit one's margin and skin bending
    terms (SkinParams.lid_bending, lip_bending, skin_bending: RK2 has none), turned off here. (From rest
    they may land in different equilibria where the compressed skin folds; see docs/simulation.md.)"""
    m = compile_model(synth_rig, SkinParams(gravity=False, lid_bending=0.0, lip_bending=0.0, skin_bending=0.0))
    c = FaceControl()
    c.set("zygomaticus_major_l", 1.0)
    c.set("frontalis_inner_r", 0.7)
    c.set("jaw", 0.4)
    rk2 = Simulator(m, wrinkles=False, method="rk2")
    state = m.rest_state()
    rk2.settle(state, c, max_seconds=3.0)
    for _ in range(120):  # well past the settle criterion
        rk2.step(state, c)
    explicit = state.positions.copy()
    motion = np.linalg.norm(explicit - m.rest, axis=1).max()
    imp = Simulator(m, wrinkles=False, method="implicit")
    state.velocities[...] = 0.0
    for _ in range(60):
        imp.step(state, c)
    assert imp.substeps < 4 and motion > 0.5
    drift = np.linalg.norm(state.positions - explicit, axis=1)
    # exact but for the eyeball contact, a projection after each step that the two methods apply
    # at different points of the step (tens of microns where skin rests on an eyeball)
    assert drift.max() < 5e-3 * motion
    # and it settles a pose from rest by itself
    c2 = FaceControl()
    c2.set("frontalis_inner_l", 1.0)
    _, a = _settled(m, c2, "implicit")
    _, b = _settled(m, c2, "rk2")
    assert np.linalg.norm(a - b, axis=1).max() < 0.05 * np.linalg.norm(b - m.rest, axis=1).max()


def test_implicit_keeps_rest_and_is_deterministic(synth_model_nograv: FaceModel) -> None:
    _, pos = _settled(synth_model_nograv, FaceControl(), "implicit")
    assert np.abs(pos - synth_model_nograv.rest).max() < 1e-9
    c = FaceControl()
    c.set("orbicularis_oris", 1.0)
    runs = []
    for _ in range(2):
        sim = Simulator(synth_model_nograv, wrinkles=False, method="implicit")
        state = synth_model_nograv.rest_state()
        for _ in range(20):
            sim.step(state, c)
        runs.append(state.positions.tobytes())
    assert runs[0] == runs[1]


def test_auto_keeps_rk2_while_it_is_cheap(synth_model: FaceModel) -> None:
    sim = Simulator(synth_model)
    assert sim.rk2_substeps * len(synth_model.spring_indices) <= RK2_WORK_LIMIT
    assert sim.method == "rk2" and sim.substeps == sim.rk2_substeps


def test_margin_bending_resists_the_zigzag_not_the_smooth_motion() -> None:
    """The lid and lip rows' bending term (sim.margin_contact.margin_bending) has no force for a
    translation and little for a displacement smooth along the rows (a lip pressed in as a whole),
    and resists the alternating zig-zag that pressed lips buckled into."""
    from sim.face import default_model
    from sim.margin_contact import margin_bending
    from sim.smoothness import margin_rows

    m = default_model(1)
    bend = margin_bending(m.mesh, m.rest, np.asarray(m.spring_indices), np.asarray(m.spring_k_high), 2.0, 1.0)
    assert bend.nnz and abs(bend - bend.T).max() < 1e-9  # an energy's Hessian
    assert np.abs(bend @ np.full(m.n_vertices, 0.3)).max() < 1e-9 * np.abs(bend).max()
    lips = margin_rows(m.mesh)["lip_upper"]
    half = 0.5 * (m.rest[lips, 0].max() - m.rest[lips, 0].min())
    smooth, zigzag = np.zeros(m.n_vertices), np.zeros(m.n_vertices)
    smooth[lips] = 0.1 * np.cos(0.5 * np.pi * m.rest[lips, 0] / half)  # 1 mm in the middle, 0 at the corners
    zigzag[lips[1:-1]] = 0.1 * (-1.0) ** np.arange(len(lips) - 2)
    assert smooth @ (bend @ smooth) < 0.02 * (zigzag @ (bend @ zigzag))


def test_a_restored_checkpoint_steps_on_to_the_same_bits() -> None:
    """The implicit integrator's lid and lip contact remembers impulses and pairs between frames;
    a state copied mid-run and restored later (a replay's scrubbing, a batch's video chunks) must
    step on exactly as the original did, whatever the simulator did in between."""
    import numpy as np

    from sim.face import default_model
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = default_model(1)
    sim = Simulator(model, 1.0 / 60.0)
    control = FaceControl(model)
    state = model.rest_state()

    def drive(k: int) -> None:
        control.set("orbicularis_oculi_lid_l", 1.0 if k % 30 < 15 else 0.0)
        control.set("orbicularis_oris", 0.8)
        control.set("jaw", 0.15 * (1.0 + np.sin(k / 7.0)))

    for k in range(20):
        drive(k)
        sim.step(state, control)
    saved = state.copy()
    assert saved.contact is not None and np.any(saved.contact)
    for k in range(20, 40):
        drive(k)
        sim.step(state, control)
    want = state.positions.copy()
    for k in range(40, 55):  # the simulator moves on elsewhere before the restore
        drive(k)
        sim.step(state, control)
    state.assign(saved)
    for k in range(20, 40):
        drive(k)
        sim.step(state, control)
    assert np.array_equal(state.positions, want)


def test_a_step_partly_computed_ahead_gives_the_same_bits() -> None:
    """The live loop computes the next step's input-free part between ticks (`Simulator.prepare`);
    replay never does. Both must give the same bits, also when the jaw or the gaze moves after the prepare or
    the state is changed under it (a restored checkpoint, a nudged vertex)."""
    from sim.face import default_model

    model = default_model(1)
    ahead, plain = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert ahead.method == "implicit"
    c = FaceControl(model)
    s_ahead, s_plain = model.rest_state(), model.rest_state()
    used = 0
    for k in range(60):
        c.set("orbicularis_oculi_lid_l", 1.0 if k % 20 < 10 else 0.0)
        c.set("zygomaticus_major_l", 0.5 + 0.5 * np.sin(k / 5.0))
        if 20 <= k < 30:
            c.set("jaw", 0.2 * (1.0 + np.sin(k / 3.0)))  # the prepare's jaw is not the step's
        if 30 <= k < 36:
            c.set("eyes_yaw", 0.1 * (k - 30))  # nor its gaze (the lids follow it as responses, sim.gaze_lids)
        ahead.prepare(s_ahead)
        impl = ahead._implicit
        assert impl is not None
        used += impl._is_predicted(s_ahead.positions, s_ahead.velocities, (ahead._jaw, ahead._skin_age))
        if k == 40:  # the state changes between the prepare and the step
            s_ahead.positions[7, 1] += 1e-3
            s_plain.positions[7, 1] += 1e-3
        ahead.step(s_ahead, c)
        plain.step(s_plain, c)
        assert s_ahead.positions.tobytes() == s_plain.positions.tobytes(), k
        assert s_ahead.velocities.tobytes() == s_plain.velocities.tobytes(), k
    assert used >= 40  # the prepared part was there to be used on most ticks


def _symmetric_reference(lu: object, arrays: dict, b: np.ndarray) -> np.ndarray:  # type: ignore[type-arg]
    """Pc L^-T D^-1 L^-1 Pr b value by value in the order `sim.supernodal._sym_sweeps` defines: the
    column sweeps' forward sweep; then run by run from the last, each unknown of the run its value
    divided by its pivot less the sum of L's column below the run times the unknowns there (lane k
    of four summing the rows k, k + 4, ... of the run's row list, then (0 + 1) + (2 + 3)), and the
    run's own unknowns from the last, each taking its later ones in turn."""
    low, up = sp.csc_matrix(lu.L), sp.csc_matrix(lu.U)  # type: ignore[attr-defined]
    n = low.shape[0]
    dense = low.toarray()
    diag = up.diagonal()
    y = _forward_sweep(lu, low, b)
    sn, rp, ri = arrays["sn_ptr"], arrays["r_ptr"], arrays["r_idx"]
    for k in range(len(sn) - 2, -1, -1):
        s, e = int(sn[k]), int(sn[k + 1])
        rows = ri[rp[k]:rp[k + 1]]
        a = {}
        for j in range(s, e):
            lanes = [np.zeros(3) for _ in range(4)]
            for i, r in enumerate(rows):
                lanes[i % 4] = lanes[i % 4] + dense[r, j] * y[r]
            a[j] = y[j] / diag[j] - ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3]))
        for j in range(e - 1, s - 1, -1):
            y[j] = a[j]
            for i in range(s, j):
                a[i] = a[i] - dense[j, i] * y[j]
    return y[lu.perm_c]  # type: ignore[attr-defined]


def test_the_solve_from_the_symmetric_factor_is_the_lu_solve_to_rounding(synth_model: FaceModel) -> None:
    """The substeps' solve from L and D alone (`sim.supernodal._sym_sweeps`, new takes: the header's
    "solve") has the bits its order defines, and the LU solve's values up to rounding, not its bits."""
    from scipy.sparse.linalg import splu

    n = synth_model.n_vertices
    a = laplacian(n, np.asarray(synth_model.spring_indices), np.asarray(synth_model.spring_k_high))
    a = (a @ a + a + sp.diags(np.asarray(synth_model.mass) * 3600.0)).tocsc()  # a wider stencil: wide runs
    solver = PrefactoredSolver(a)
    assert solver.symmetric
    widths, below = np.diff(solver.arrays["sn_ptr"]), np.diff(solver.arrays["r_ptr"])
    assert widths.max() >= 8 and (widths == 1).any() and (below % 4 != 0).any()  # wide runs, lone columns, tails
    lu = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    rng = np.random.default_rng(12)
    differ = 0
    for _ in range(3):
        b = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, size=(n, 1))
        sym, full = np.zeros_like(b), np.zeros_like(b)
        solver.solve_symmetric(b, sym)
        solver.solve(b, full)
        assert sym.tobytes() == _symmetric_reference(lu, solver.arrays, b).tobytes()
        assert np.abs(sym - full).max() <= 1e-13 * np.abs(full).max()
        assert np.abs(a @ sym - b).max() <= 1e-12 * (abs(a) @ np.abs(sym)).max()  # a backward-stable solve
        differ += int(np.count_nonzero(sym != full))
    assert differ  # other bits: what the take header is for


def test_the_symmetric_solve_steps_to_the_same_face_up_to_rounding(synth_model_nograv: FaceModel) -> None:
    c = FaceControl()
    c.set("orbicularis_oris", 1.0)
    out = {}
    for on in (True, False):
        sim = Simulator(synth_model_nograv, wrinkles=False, method="implicit")
        assert sim.symmetric_solve  # new simulators solve from the symmetric factor
        sim.symmetric_solve = on
        state = synth_model_nograv.rest_state()
        for _ in range(30):
            sim.step(state, c)
        out[on] = state.positions.copy()
    moved = np.abs(out[False] - synth_model_nograv.rest).max()
    assert moved > 1e-3
    assert 0.0 < np.abs(out[True] - out[False]).max() < 1e-9 * moved


def test_the_springs_local_step_by_runs_has_the_bits_of_one_pass() -> None:
    """The local step's scatter with each run's shared first node kept in registers, its indices
    flat and unsigned and k_low scaled as it is read (`_pd_springs` on `spring_layout`) adds to
    each node the very bits of one pass in spring order over k_low multiplied into an array."""
    import math

    from sim.implicit import _pd_springs, spring_layout

    rng = np.random.default_rng(3)
    n = 30
    pairs = np.array([(i, j) for i in range(n) for j in range(n) if i != j and rng.random() < 0.15])
    springs = np.ascontiguousarray(pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))], dtype=np.int32)
    m = len(springs)
    rest_len, k_low, k_high = rng.uniform(0.5, 1.5, m), rng.uniform(1.0, 2.0, m), rng.uniform(20.0, 40.0, m)
    runs, si3, sj3 = spring_layout(springs)
    assert len(runs) - 1 < m  # runs longer than one spring
    for scale in (1.0, 0.83, 0.6):
        y = rng.normal(0.0, 1.0, (n, 3))
        base = rng.normal(0.0, 1.0, (n, 3))
        want, got = base.copy(), base.copy()
        kl = k_low * scale
        for s, (i, j) in enumerate(springs):  # one pass, as the kernel was written before
            d = y[j] - y[i]
            r = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            stretch = r - rest_len[s]
            knee = 0.1 * rest_len[s]
            t = kl[s] * stretch if stretch <= knee else kl[s] * knee + k_high[s] * (stretch - knee)
            f = ((k_high[s] * r - t) / r) * d
            want[j] += f
            want[i] -= f
        _pd_springs(y, runs, si3, sj3, rest_len, k_low, scale, k_high, 0.1, got, np.zeros((3, m)))
        assert got.tobytes() == want.tobytes(), scale
    with pytest.raises(ValueError, match="itself"):
        spring_layout(np.array([[0, 1], [2, 2]]))


def test_the_bit_comparison_sees_one_bit() -> None:
    """The check that a state is the one a prediction was made from (`_same_bits`) tells a sign
    of zero or the last bit of one value apart, and nothing else."""
    from sim.implicit import _same_bits

    a = np.random.default_rng(5).normal(size=3001)
    a[17] = 0.0
    assert _same_bits(a.view(np.int64), a.copy().view(np.int64))
    for k, changed in ((17, -0.0), (3000, np.nextafter(a[3000], 1.0)), (0, np.nextafter(a[0], -1.0))):
        b = a.copy()
        b[k] = changed
        assert not _same_bits(a.view(np.int64), b.view(np.int64)), k


def test_the_right_hand_side_sums_the_held_coupling_as_the_product_does(synth_model: FaceModel) -> None:
    """The solve's right-hand side (`_held_rhs`) is base + ext less the held nodes' coupling, each
    row's coupling summed as the flat product sums it (`_csr_times_flat`), in the factors' row
    order: the same bits as the product made first into an array."""
    from sim.implicit import _csr_times_flat, _held_rhs

    sim = Simulator(synth_model, method="implicit")
    imp = sim._implicit
    assert imp is not None and len(imp.held) and len(imp._fh[2])
    rng = np.random.default_rng(4)
    x, base, ext = (rng.normal(0.0, 1.0, (synth_model.n_vertices, 3)) for _ in range(3))
    nf = len(imp.free)
    for summed in (False, True):
        coupling = np.zeros((nf, 3))
        _csr_times_flat(*imp._fh, np.ascontiguousarray(x[imp.held]).reshape(-1), coupling)
        want = np.zeros((nf, 3))
        want[imp.solver.perm_r] = (base[imp.free] if summed else base[imp.free] + ext[imp.free]) - coupling
        got = np.full((nf, 3), np.nan)
        _held_rhs(x, imp.held, *imp._fh, base, ext, imp.free, imp.solver.perm_r, np.zeros((len(imp.held), 3)), got,
                  summed)
        assert got.tobytes() == want.tobytes(), summed
