"""The implicit step starts from the state's last jaw opening and skin age and moves the jaw by its
precomputed responses (`Simulator.jaw_responses`): a moved jaw or age takes the prepared step (no
whole step at the input), the jaw moves in the step that takes it, replays keep their bits, and the
face settles where the whole step settles it."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face import default_model
from sim.integrator import Simulator
from sim.state import FaceControl


@pytest.fixture(scope="module")
def model():  # type: ignore[no-untyped-def]
    return default_model(1)  # fine enough for the implicit integrator


def _chin(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.flatnonzero((np.asarray(model.jaw_weight) > 0.5) & ~np.asarray(model.held))


def test_a_moving_jaw_and_age_take_the_step_prepared_ahead_with_the_same_bits(model) -> None:  # type: ignore[no-untyped-def]
    ahead, plain = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert ahead.method == "implicit" and ahead.jaw_responses
    c = FaceControl(model)
    s_ahead, s_plain = model.rest_state(), model.rest_state()
    used = 0
    for k in range(40):
        c.set("jaw", 0.3 * (1.0 + np.sin(k / 4.0)))  # moves every tick
        c.set("age", 40.0 + k)
        c.set("zygomaticus_major_l", 0.5)
        ahead.prepare(s_ahead)
        impl = ahead._implicit
        assert impl is not None
        used += impl._is_predicted(s_ahead.positions, s_ahead.velocities, (ahead._jaw, ahead._skin_age))
        ahead.step(s_ahead, c)
        plain.step(s_plain, c)
        assert s_ahead.positions.tobytes() == s_plain.positions.tobytes(), k
        assert s_ahead.velocities.tobytes() == s_plain.velocities.tobytes(), k
    assert used == 40  # every step, the jaw and the age moving included, found its part made ahead


def test_the_jaw_moves_in_the_step_that_takes_it(model) -> None:  # type: ignore[no-untyped-def]
    """One tick opens the jaw: the held chin edge is on the opened jaw's target at once and the free
    chin follows about as far as the whole step moves it."""
    fast, whole = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    whole.jaw_responses = False
    c = FaceControl(model)
    state = model.rest_state()
    fast.settle(state, c, max_seconds=1.0)
    chin, held = _chin(model), np.flatnonzero(model.held)
    c.set("jaw", 0.5)
    moved = {}
    for name, s in (("fast", fast), ("whole", whole)):
        st = state.copy()
        s.step(st, c)
        moved[name] = st.positions - state.positions
        np.testing.assert_array_equal(st.positions[held], s._target[held])  # (the constants' grid: within 5 um
        np.testing.assert_allclose(s._target[held], s.rest_target(0.5)[held], rtol=0, atol=5e-4)  # of the turn)
    down_fast, down_whole = -moved["fast"][chin, 1].mean(), -moved["whole"][chin, 1].mean()
    assert down_whole > 0.0
    assert 0.85 * down_whole < down_fast < 1.15 * down_whole


def test_the_jaw_as_responses_settles_where_the_whole_step_does(model) -> None:  # type: ignore[no-untyped-def]
    """While the jaw opens the two steps part a little (the step from the last pose sees the held
    edge's springs and the support's normals as they were a tick before); held open, they meet."""
    fast, whole = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    whole.jaw_responses = False
    c = FaceControl(model)
    sf, sw = model.rest_state(), model.rest_state()
    chin = _chin(model)
    worst = 0.0
    for k in range(480):
        c.set("jaw", 0.7 * min(1.0, k / 36))  # opened over 0.3 s, then held
        fast.step(sf, c)
        whole.step(sw, c)
        worst = max(worst, float(np.abs(sf.positions - sw.positions).max()))
    travel = float(np.linalg.norm(sw.positions[chin] - model.rest[chin], axis=1).max())
    assert worst < 0.002 * travel  # under 0.1 mm on a 3.5 cm travel of the chin
    assert np.abs(sf.positions - sw.positions).max() < 1e-5 * travel


def test_the_flat_product_has_the_bits_of_the_sparse_product() -> None:
    """The margin bending's rest side, made every tick while the jaw moves (`_csr_times_flat`), is
    scipy's product K_b x to the bit, empty rows included."""
    import scipy.sparse as sp

    from sim.implicit import _csr_times_flat, _flat_csr

    rng = np.random.default_rng(7)
    a = sp.random(300, 280, density=0.06, random_state=11, format="csr")
    a.data = rng.normal(size=a.nnz) * 10.0 ** rng.integers(-6, 6, size=a.nnz)
    a.data[a.indptr[5]:a.indptr[6]] = 0.0  # an empty row
    a.eliminate_zeros()
    x = rng.normal(size=(280, 3)) * 10.0 ** rng.integers(-3, 3, size=(280, 1))
    out = np.full((300, 3), np.nan)
    _csr_times_flat(*_flat_csr(a.indptr, a.indices, a.data), x.reshape(-1), out)
    assert out.tobytes() == (a @ x).tobytes()
    assert not out[5].any()


def test_the_muscles_responses_four_a_pass_have_the_bits_of_one_channel_a_pass() -> None:
    """The muscles' responses summed four channels a pass (`_responses`) give each value the bits
    of the sum a channel at a time from 0, whatever the number of channels (signed zeros too), so
    takes keep their bits."""
    from sim.implicit import _responses

    rng = np.random.default_rng(5)
    resp = rng.normal(size=(12, 40, 3)) * 10.0 ** rng.integers(-4, 4, size=(12, 40, 1))
    resp[3, :5] = -0.0
    for count in range(10):
        act = rng.permutation(12)[:count].astype(np.int64)
        val = rng.uniform(-1.0, 1.0, size=count)
        want = np.zeros((40, 3))
        for k in range(count):
            want += resp[act[k]] * val[k]
        out = np.full((40, 3), np.nan)
        _responses(resp, act, val, out)
        assert out.tobytes() == want.tobytes(), count
    act = np.array([3], dtype=np.int64)
    out = np.full((40, 3), np.nan)
    _responses(resp, act, np.array([1.0]), out)
    assert not np.signbit(out[:5]).any()  # 0 + (-0) * 1: a sum from 0, as a pass a channel made it


def test_the_jaw_rotation_has_the_bits_of_rodrigues_in_numpy() -> None:
    """`jaw_rotation` (spelled out on floats, made every tick the jaw moves) gives each entry of
    I + sin(t) K + (1 - cos(t)) K K as numpy's elementwise formula does, so takes keep their bits."""
    import math

    from sim.integrator import jaw_rotation

    rng = np.random.default_rng(3)
    for k in range(300):
        axis = rng.normal(size=3)
        axis /= math.sqrt(float(axis @ axis))
        angle = float(rng.uniform(-0.6, 0.6)) if k % 10 else 0.0
        kx = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        kk = np.stack([kx[:, 0] * kx[0, j] + kx[:, 1] * kx[1, j] + kx[:, 2] * kx[2, j] for j in range(3)], axis=-1)
        want = np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kk
        assert jaw_rotation(axis, angle).tobytes() == want.tobytes(), k
    r = jaw_rotation(np.array([0.0, 0.0, 1.0]), math.pi / 2)
    assert np.allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # a quarter turn about z takes x to y


def test_the_jaw_move_sums_its_three_terms_in_order() -> None:
    """`_jaw_moves` (one flat pass) gives each value what three numpy passes give it: the response
    at the new opening, minus the one at the old, plus the slope times the move, each linear
    between the grid's openings, added to what du holds or from zero."""
    from sim.implicit import _jaw_moves

    rng = np.random.default_rng(5)
    jr, js = rng.normal(size=(9, 40, 3)), rng.normal(size=(9, 40, 3))
    held = rng.normal(size=(40, 3))

    def lerp(grid: np.ndarray, t: float) -> np.ndarray:
        k = min(int(t * 8), 7)
        f = t * 8 - k
        return grid[k] + f * (grid[k + 1] - grid[k])

    for a, b in ((0.31, 0.37), (0.9, 0.2), (0.0, 1.0), (0.5, 0.5)):
        for add in (True, False):
            du = held.copy()
            _jaw_moves(jr, js, a, b, du, add, False)
            want = held.copy() if add else np.zeros_like(held)
            want += 1.0 * lerp(jr, b)
            want += -1.0 * lerp(jr, a)
            want += (b - a) * lerp(js, 0.5 * (a + b))
            assert du.tobytes() == want.tobytes(), (a, b, add)


def test_a_jaw_move_within_a_grid_step_reads_two_rows_for_the_same_move() -> None:
    """With float32 responses (`single_responses`) a move between two openings in the same grid
    step is the fraction's change times the step's difference: the same move as the two lerps'
    difference to rounding, exactly none for no move, and the general way across steps."""
    from sim.implicit import _jaw_moves

    rng = np.random.default_rng(6)
    jr, js = rng.normal(size=(9, 40, 3)).astype(np.float32), rng.normal(size=(9, 40, 3)).astype(np.float32)
    held = rng.normal(size=(40, 3))
    for a, b in ((0.31, 0.33), (0.33, 0.31), (0.5, 0.5), (0.9, 0.2), (0.0, 0.1)):
        du, general = held.copy(), held.copy()
        _jaw_moves(jr, js, a, b, du, True, True)
        _jaw_moves(jr, js, a, b, general, True, False)
        np.testing.assert_allclose(du, general, rtol=0, atol=1e-14)
        if int(a * 8) != int(b * 8):
            assert du.tobytes() == general.tobytes()
        if a == b:
            assert du.tobytes() == held.tobytes()


def test_the_springs_follow_the_age_law_whichever_scale_moves(model, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The collagen's stiffness k_h is rescaled only when its scale changes (the age law keeps it):
    a law that does soften it at some age gets it softened there and back at the others."""
    from sim.wrinkles import aging

    law = aging.skin_params_for_age

    def softer_when_old(age: float, base: float = 0.15) -> aging.SkinParams:
        p = law(age, base)
        return aging.SkinParams(p.k_low_scale, 0.5 if age >= 70.0 else p.k_high_scale, p.strain_threshold)

    monkeypatch.setattr(aging, "skin_params_for_age", softer_when_old)
    s = Simulator(model, 1.0 / 120.0)
    base_low, base_high = s._k_low_base, s._k_high_base
    for age in (30.0, 50.0, 75.0, 80.0, 60.0, 90.0, 40.0):
        s._age_skin(age)
        p = softer_when_old(age, float(model.strain_threshold))
        assert s._k_low.tobytes() == (base_low * p.k_low_scale).tobytes(), age
        assert s._k_high.tobytes() == (base_high * p.k_high_scale).tobytes(), age


def test_the_turned_normals_and_fixed_forces_have_the_bits_of_numpy(model) -> None:  # type: ignore[no-untyped-def]
    """A new jaw pose's support normals are numpy's unit rows of the turned normals to the bit,
    its target, rest shape and held nodes numpy's turn (`_jaw_pose`), and the implicit step's
    constant forces without muscles (`_fixed_forces`, and `_jaw_pose`'s) are the muscle kernel's
    with none counted: what takes recorded before were stepped with."""
    from sim.integrator import _constant_forces, _fixed_forces, _jaw_pose

    s = Simulator(model, 1.0 / 120.0)
    s.bending_turned = False  # the turned rest shape too, which takes without "jaw bending" use
    m = s.model
    for jaw in (0.05, 0.4, 1.0):
        rot = np.ascontiguousarray(s._jaw_motion((jaw, 0.0, 0.0))[0])
        n, w = np.asarray(m.rest_normal), np.asarray(m.jaw_weight)[:, None]
        turned = n + w * (np.stack([n[:, 0] * rot[j, 0] + n[:, 1] * rot[j, 1] + n[:, 2] * rot[j, 2] for j in range(3)], axis=-1) - n)
        want = turned / np.sqrt((turned[:, 0] * turned[:, 0] + turned[:, 1] * turned[:, 1]) + turned[:, 2] * turned[:, 2])[:, None]
        got, none = np.zeros_like(want), np.zeros((0, 3))
        _jaw_pose(s._rest3, s._offset3, np.array(n.T), s._pivot, np.array(w[:, 0]), rot, s._jaw_motion((jaw, 0.0, 0.0))[1],
                  np.zeros_like(want), none, got, np.zeros((10, len(n))), s._weight, s._kr, s._kn, none)
        assert got.tobytes() == want.tobytes(), jaw
        s._set_jaw((jaw, 0.0, 0.0))
        assert s._normal.tobytes() == want.tobytes(), jaw
        fixed_then = np.full_like(want, np.nan)  # made with the pose's target and normals (`_jaw_pose`)
        _fixed_forces(s._weight, s._kr, s._target, s._kn, s._normal, fixed_then)
        assert s._const_jaw == (jaw, 0.0, 0.0) and s._ext_const.tobytes() == fixed_then.tobytes(), jaw
        rest, offset = np.asarray(m.rest), np.asarray(m.rest_offset)
        pivot, slide = np.asarray(m.jaw_pivot, dtype=np.float64), s._jaw_motion((jaw, 0.0, 0.0))[1]

        def times(a: np.ndarray) -> np.ndarray:
            return np.stack([a[:, 0] * rot[j, 0] + a[:, 1] * rot[j, 1] + a[:, 2] * rot[j, 2] for j in range(3)], axis=-1)

        turned = times(rest - pivot) + pivot
        base = rest + offset
        want_target = base + w * (turned + times(offset) + slide - base)
        assert s._target.tobytes() == want_target.tobytes(), jaw
        assert s._shape.tobytes() == (rest + w * (turned + slide - rest)).tobytes(), jaw
        held = np.zeros_like(rest)
        s._set_jaw((0.0, 0.0, 0.0))
        s._place_held(held, (jaw, 0.0, 0.0))
        assert held[s._held].tobytes() == want_target[s._held].tobytes(), jaw
        target = s.rest_target(jaw)
        mm = m.muscle_matrix
        summed, fixed = np.zeros_like(target), np.full_like(target, np.nan)
        _constant_forces(np.zeros_like(mm.indptr), mm.indices, mm.data, np.zeros(len(s._is_muscle)), s._is_muscle,
                         s._weight, s._kr, target, s._kn, got, summed)
        _fixed_forces(s._weight, s._kr, target, s._kn, got, fixed)
        assert fixed.tobytes() == summed.tobytes(), jaw
    rows, none = np.zeros((2, 3)), np.zeros((0, 3))
    with pytest.raises(ZeroDivisionError):
        _jaw_pose(np.ones((3, 2)), np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), np.zeros(2), np.eye(3),
                  np.zeros(3), rows, none, rows.copy(), np.zeros((10, 2)), np.ones((2, 3)), np.ones(2), np.ones(2), none)


def test_the_bending_rest_side_from_the_turn_is_the_product_with_the_turned_shape(model) -> None:  # type: ignore[no-untyped-def]
    """The margin bending's rest side made from the jaw's turn (`Simulator.bending_turned`,
    `_bend_turned`) is K_b times the rest shape turned with the jaw, opened, thrust or moved
    sideways, to rounding."""
    from sim.implicit import _bend_turned, _csr_times_flat

    s = Simulator(model, 1.0 / 120.0)
    impl = s._implicit
    assert impl is not None and len(impl._bend[2])  # the face has margin bending rows
    for pose in ((0.4, 0.0, 0.0), (1.0, 0.0, 0.0), (0.3, 0.6, 0.0), (0.5, 0.0, -0.8)):
        shape = s.rest_target(*pose[:1], offset=False, forward=pose[1], sideways=pose[2])
        want = np.zeros_like(shape)
        _csr_times_flat(*impl._bend_flat, shape.reshape(-1), want)
        rot, slide = s._jaw_motion(pose)
        got = np.full_like(shape, np.nan)
        _bend_turned(*impl._turn_b, np.ascontiguousarray(rot), np.ascontiguousarray(slide), got)
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max(), pose
        assert np.abs(want - impl._turn_b[0] - impl._turn_b[1]).max() > 0.0  # the turn changes it


def test_the_bending_from_the_turn_moves_the_face_as_the_product_does(model) -> None:  # type: ignore[no-untyped-def]
    """Stepped with the bending's rest side from the jaw's turn or from the product, the face
    moves and settles the same to rounding (under 1e-9 of the chin's travel) while the jaw opens
    and the skin ages; with the jaw shut the two are the same bits (takes without the jaw keep
    theirs)."""
    turned, product = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert turned.bending_turned
    product.bending_turned = False
    turned.constants_from_grid = False  # (the bending alone differs: the jaw's constants turned both ways)
    c = FaceControl(model)
    st, sp_ = model.rest_state(), model.rest_state()
    c.set("zygomaticus_major_l", 0.6)
    for k in range(20):  # the jaw shut: the product with the rest shape either way
        turned.step(st, c)
        product.step(sp_, c)
    assert st.positions.tobytes() == sp_.positions.tobytes()
    worst = 0.0
    for k in range(240):
        c.set("jaw", 0.7 * min(1.0, k / 36))
        c.set("age", 30.0 + 40.0 * min(1.0, k / 60))
        for s, state in ((turned, st), (product, sp_)):
            s.step(state, c)
            s.prepare(state)
        worst = max(worst, float(np.abs(st.positions - sp_.positions).max()))
    chin = _chin(model)
    travel = float(np.linalg.norm(sp_.positions[chin] - model.rest[chin], axis=1).max())
    assert st.positions.tobytes() != sp_.positions.tobytes()  # other bits: the header says which
    assert worst < 1e-9 * travel


def test_the_active_muscles_and_the_bending_added_have_the_bits_of_numpy(model) -> None:  # type: ignore[no-untyped-def]
    """The step's small kernels give numpy's answers to the bit: the active muscle channels and
    their values (`_active`: flatnonzero and gather, a NaN counted as active as numpy does), and
    the margin bending's rest side from the turn added to the constant forces in its own pass
    (`_bend_turned_add`: `_bend_turned` then np.add)."""
    from sim.implicit import _bend_turned, _bend_turned_add
    from sim.integrator import _active

    s = Simulator(model, 1.0 / 120.0)
    rng = np.random.default_rng(11)
    for k in range(5):
        v = np.where(rng.random(len(s._is_muscle)) < 0.4, rng.uniform(-1.0, 1.0, len(s._is_muscle)), 0.0)
        v[3] = -0.0
        if k == 4:
            v[np.flatnonzero(s._is_muscle)[2]] = np.nan
        act, val = np.zeros(len(v), dtype=np.int64), np.zeros(len(v))
        count = _active(v, s._is_muscle, act, val)
        want = np.flatnonzero(s._is_muscle & (v != 0.0))
        assert act[:count].tobytes() == want.tobytes() and val[:count].tobytes() == v[want].tobytes(), k
    impl = s._implicit
    ext = rng.normal(0.0, 1.0, (model.n_vertices, 3))
    for pose in ((0.4, 0.0, 0.0), (0.3, 0.6, -0.2)):
        rot, slide = s._jaw_motion(pose)
        bend, want = np.zeros_like(ext), np.zeros_like(ext)
        _bend_turned(*impl._turn_b, rot, slide, bend)
        np.add(ext, bend, out=want)
        got_bend, got = np.full_like(ext, np.nan), np.full_like(ext, np.nan)
        _bend_turned_add(*impl._turn_b, rot, slide, ext, got_bend, got)
        assert got_bend.tobytes() == bend.tobytes() and got.tobytes() == want.tobytes(), pose


def test_the_right_hand_side_with_the_turned_bending_has_the_bits_of_the_sum_made_first(model) -> None:  # type: ignore[no-untyped-def]
    """The prediction's right-hand side with the margin bending's rest side turned with the jaw made
    row by row where it is used (`_held_rhs_turned`) has the bits of that side added to the
    constant forces into an array first (`_bend_turned_add`) and then read (`_held_rhs`)."""
    from sim.implicit import _bend_turned_add, _held_rhs, _held_rhs_turned

    s = Simulator(model, 1.0 / 120.0)
    impl = s._implicit
    assert impl is not None and len(impl.held) and len(impl._bend[2])
    rng = np.random.default_rng(5)
    x, base, ext = (rng.normal(0.0, 1.0, (model.n_vertices, 3)) for _ in range(3))
    free, held, perm_r = impl._index[:3]
    nf, nh = len(impl.free), len(impl.held)
    for pose in ((0.4, 0.0, 0.0), (0.3, 0.6, -0.2)):
        rot, slide = s._jaw_motion(pose)
        total = np.zeros_like(ext)
        _bend_turned_add(*impl._turn_b, rot, slide, ext, np.zeros_like(ext), total)
        want, got = np.full((nf, 3), np.nan), np.full((nf, 3), np.nan)
        _held_rhs(x, held, *impl._fh, base, total, free, perm_r, np.zeros((nh, 3)), want, False)
        _held_rhs_turned(x, held, *impl._fh, base, ext, *impl._turn_b, rot, slide, free, perm_r, np.zeros((nh, 3)), got)
        assert np.all(np.isfinite(got)) and got.tobytes() == want.tobytes(), pose


def test_a_jaw_opening_made_in_one_call_has_the_bits_of_the_motion_the_pose_and_the_placement(model) -> None:  # type: ignore[no-untyped-def]
    """A new opening (no thrust or sideways move: a jaw dial's every tick) is made by one kernel
    (`_set_opening`); its rotation, slide, target, normals, constant forces and held nodes are
    those of `jaw_motion`, `_jaw_pose` and the placement one after the other, NaN included, and a
    thrust or a replay's other bending still takes the general way with the same values."""
    from sim.integrator import _jaw_pose, jaw_motion

    s, plain = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert s._opening_fast
    s.constants_from_grid = False  # (the turn's constants, as takes recorded before the grid's)
    rng = np.random.default_rng(8)
    n = model.n_vertices
    for jaw in [*rng.uniform(-0.2, 1.3, 12), 1e-300, -5e-324, 1.0, float("nan")]:
        x = rng.normal(0.0, 1.0, (n, 3))
        want_x = x.copy()
        s._set_jaw((0.0, 0.0, 0.0))
        s._place_held(x, (float(jaw), 0.0, 0.0))
        rot, slide = jaw_motion(model, float(jaw), slide_one=s._slide_one)
        target, normal, fixed = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
        _jaw_pose(plain._rest3, plain._offset3, plain._normal3, plain._pivot, plain._jaw_weight,
                  np.ascontiguousarray(rot), slide, target, np.zeros((0, 3)), normal, np.zeros((10, n)),
                  plain._weight, plain._kr, plain._kn, fixed)
        want_x[s._held] = target[s._held]
        assert s._shape.rot.tobytes() == np.ascontiguousarray(rot).tobytes(), jaw
        assert s._shape.slide.tobytes() == slide.tobytes(), jaw
        for got, want in ((s._target, target), (s._normal, normal), (s._ext_const, fixed), (x, want_x)):
            assert got.tobytes() == want.tobytes(), jaw
        assert s._const_jaw == s._jaw == (float(jaw), 0.0, 0.0) or np.isnan(jaw)
    s.bending_turned = False  # (a take recorded before the bending from the turn)
    assert not s._opening_fast
    s._set_jaw((0.4, 0.0, 0.0))
    assert isinstance(s._shape, np.ndarray)


def test_the_bending_sum_kept_for_a_key_is_made_again_for_another(model) -> None:  # type: ignore[no-untyped-def]
    """`predict` keeps the constant forces plus the margin bending's rest side while its key names
    the same forces (a jaw at rest, tick after tick), and makes it again when the key changes,
    even if the forces' array is the same one rewritten in place."""
    s = Simulator(model, 1.0 / 120.0)
    impl = s._implicit
    assert impl is not None and len(impl._bend[2])
    shape = np.array(model.rest)
    ext = np.random.default_rng(2).normal(0.0, 1.0, (model.n_vertices, 3))
    first = impl._with_bending(ext, shape, ("a", 1.0)).copy()
    ext *= 2.0  # in place: only the key tells
    kept = impl._with_bending(ext, shape, ("a", 1.0))
    assert kept.tobytes() == first.tobytes()
    again = impl._with_bending(ext, shape, ("b", 1.0))
    assert again.tobytes() == (ext + impl._bend_rhs).tobytes() != first.tobytes()
    assert impl._with_bending(ext, shape).tobytes() == again.tobytes()  # no key: always made


def test_a_state_with_another_contact_memory_steps_from_its_own(model) -> None:  # type: ignore[no-untyped-def]
    """The contact's arrays are recalled from each state's memory unless they hold it already: one
    simulator stepping two states in turn (each prepared first, as the live loop does) steps each
    as a simulator of its own does, to the bit."""
    c = FaceControl(model)
    c.set("orbicularis_oris", 0.8)  # the lips pressed together: the contact acts
    shared, alone_a, alone_b = (Simulator(model, 1.0 / 120.0) for _ in range(3))
    a = model.rest_state()
    for _ in range(6):
        alone_a.step(a, c)
    b = model.rest_state()
    mine = {"a": a.copy(), "b": b.copy()}
    for k in range(8):
        c.set("jaw", 0.02 * k)
        for name, st, alone in (("a", a, alone_a), ("b", b, alone_b)):
            shared.prepare(mine[name])
            shared.step(mine[name], c)
            alone.prepare(st)
            alone.step(st, c)
            assert mine[name].positions.tobytes() == st.positions.tobytes(), (k, name)
            assert mine[name].contact.tobytes() == st.contact.tobytes(), (k, name)
    assert np.any(a.contact != b.contact)


def test_the_jaw_constants_from_the_grid_are_the_turns_to_a_few_micrometres(model) -> None:  # type: ignore[no-untyped-def]
    """Read between the grid's openings, eq 9's target lies within 5 um of the turned one (the
    chord of a 1-degree arc), the support normals are unit and within 2e-5 of the turned ones,
    the constant forces are made from those rows, the held nodes sit on the target; on the grid's
    openings all of it is the turn's to float32 rounding; at rest the rest pose's very bits."""
    from sim.integrator import JAW_GRID, _fixed_forces

    grid, turn = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert grid.constants_from_grid
    turn.constants_from_grid = False
    n = model.n_vertices
    rng = np.random.default_rng(3)
    for jaw in [*rng.uniform(0.0, 1.0, 8), 0.5 / JAW_GRID, 1e-9, 1.0, 7 / JAW_GRID]:
        x = rng.normal(0.0, 1.0, (n, 3))
        grid._place_held(x, (float(jaw), 0.0, 0.0))
        turn._set_jaw((float(jaw), 0.0, 0.0))
        on_grid = float(jaw) * JAW_GRID == round(float(jaw) * JAW_GRID)
        near = 1e-6 if on_grid else 5e-4  # cm
        assert np.abs(grid._target - turn._target).max() < near, jaw
        assert np.abs(grid._normal - turn._normal).max() < (1e-7 if on_grid else 2e-5), jaw
        assert np.abs(np.linalg.norm(grid._normal, axis=1) - 1.0).max() < 1e-8, jaw
        fixed = np.zeros((n, 3))
        _fixed_forces(grid._weight, grid._kr, grid._target, grid._kn, grid._normal, fixed)
        np.testing.assert_allclose(grid._ext_const, fixed, rtol=0, atol=1e-12 * np.abs(fixed).max())
        np.testing.assert_array_equal(x[grid._held], grid._target[grid._held])
        assert grid._shape.rot.tobytes() == turn._shape.rot.tobytes()  # (the bending's turn: exact)
    for s in (grid, turn):
        s._set_jaw((0.0, 0.0, 0.0))
    assert grid._target.tobytes() == turn._target.tobytes()
    assert grid._normal.tobytes() == turn._normal.tobytes()


def test_float32_responses_and_the_jaw_grid_move_the_face_as_before(model) -> None:  # type: ignore[no-untyped-def]
    """Stepped with the inputs' responses in float32 and the jaw's constants from the grid, or
    with both as before (float64, the turn), the face at rest keeps the very same bits (no input
    reads a response), and while the jaw opens, the skin ages and a smile comes, and once held,
    the two part by under 1e-3 of the chin's travel (procedural face: ~7 um on 3.5 cm, the
    constants' chord); other bits (the take header's "responses" and "jaw constants")."""
    new, old = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert new.single_responses and new.constants_from_grid
    old.single_responses = old.constants_from_grid = False
    c = FaceControl(model)
    sn, so = model.rest_state(), model.rest_state()
    for _ in range(30):
        new.step(sn, c)
        old.step(so, c)
    assert sn.positions.tobytes() == so.positions.tobytes()
    worst = 0.0
    for k in range(360):
        c.set("jaw", 0.7 * min(1.0, k / 36))
        c.set("age", 30.0 + 40.0 * min(1.0, k / 60))
        c.set("zygomaticus_major_l", 0.6 if k > 20 else 0.0)
        for s, state in ((new, sn), (old, so)):
            s.step(state, c)
            s.prepare(state)
        worst = max(worst, float(np.abs(sn.positions - so.positions).max()))
    chin = _chin(model)
    travel = float(np.linalg.norm(so.positions[chin] - model.rest[chin], axis=1).max())
    assert travel > 1.0
    assert sn.positions.tobytes() != so.positions.tobytes()
    assert worst < 1e-3 * travel


def test_the_float32_responses_follow_responses_set_anew_or_changed_in_place(model) -> None:  # type: ignore[no-untyped-def]
    """A fit that sets a channel's response anew, or changes it in place and says so, moves the
    face by the new response with float32 responses: a channel's response doubled at 0.5 steps
    to the bits of the original at 1.0 (the doubling is exact in float32); unsaid, the old copy."""
    ci = model.channel_index["zygomaticus_major_l"]
    c_full, c_half = FaceControl(model), FaceControl(model)
    c_full.set("zygomaticus_major_l", 1.0)
    c_half.set("zygomaticus_major_l", 0.5)
    plain, set_anew, in_place = (Simulator(model, 1.0 / 120.0) for _ in range(3))
    set_anew._implicit._resp = np.array(set_anew._implicit._resp)  # (a copy of its own, then doubled)
    set_anew._implicit._resp = set_anew._implicit._resp * np.where(np.arange(len(set_anew._implicit._resp)) == ci,
                                                                   2.0, 1.0)[:, None, None]
    in_place._implicit._resp = np.array(in_place._implicit._resp)
    in_place._implicit._resp[ci] *= 2.0
    states = [model.rest_state() for _ in range(4)]
    for k in range(5):
        plain.step(states[0], c_full)
        set_anew.step(states[1], c_half)
        in_place.step(states[2], c_half)  # the copy made before the change: not the doubled response
    assert states[1].positions.tobytes() == states[0].positions.tobytes()
    assert states[2].positions.tobytes() != states[0].positions.tobytes()
    in_place._implicit.responses_changed()
    for k in range(5):
        in_place.step(states[3], c_half)
    assert states[3].positions.tobytes() == states[0].positions.tobytes()
