"""The tether's anchors moved with a channel (sim.face.scan.anchor_fit) on the synthetic face: the
added force is external (it carries a zone as a whole, where active strain's sums to zero), the
right side's field is the left's mirrored, and the fit's gradient is its objective's."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def cal(synth_model):  # type: ignore[no-untyped-def]
    from sim.face.scan.anchor_fit import AnchorCalibration

    return AnchorCalibration(synth_model)


def test_anchors_moved_up_carry_their_zone_up(cal, synth_model) -> None:  # type: ignore[no-untyped-def]
    """Every anchor of one channel's zone raised 1 mm: a net force up (the tether pulls the skin
    towards its displaced anchors) and the zone's skin carried up with them, by most of the mm
    where the zone is wide, not pushed apart inside it."""
    ch = "zygomaticus_major_l"
    par, _ = cal.par_of[ch]
    zone = par >= 0
    p = np.zeros(cal.n_params).reshape(-1, 3)
    p[par[zone], 1] = 1.0
    f = cal.force(ch, p.ravel())
    kr = np.asarray(synth_model.rest_stiffness)
    assert np.allclose(f[zone, 1], 0.1 * kr[zone]) and not f[~zone].any()
    vals = np.zeros((1, len(synth_model.channels)))
    vals[0, synth_model.channel_index[ch]] = 1.0
    u = cal.predict_all(vals, p.ravel())[0]
    up = u[zone, 1]
    assert up.mean() > 0.02  # cm: a fifth of the anchors' mm at least, on average over the zone
    assert np.abs(u[zone, 0]).mean() < 0.5 * up.mean() and np.abs(u[zone, 2]).mean() < 0.5 * up.mean()
    assert (up > 0).mean() > 0.95


def test_the_right_side_mirrors_the_left(cal, synth_model) -> None:  # type: ignore[no-untyped-def]
    from sim.face.scan.insertion_fit import mirror_map

    rest = np.asarray(synth_model.rest)
    mirror = mirror_map(rest)
    p = np.random.default_rng(2).standard_normal(cal.n_params)
    left, right = cal.field("zygomaticus_major_l", p), cal.field("zygomaticus_major_r", p)
    zone = np.flatnonzero(np.linalg.norm(right, axis=1) > 0)
    assert len(zone) > 10
    assert np.allclose(right[zone], left[mirror[zone]] * np.array([-1.0, 1.0, 1.0]))


def test_the_fits_gradient_is_its_objectives(cal, synth_model) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(5)
    chans = list(cal.force_of)[:3]
    vals = np.zeros((2, len(synth_model.channels)))
    for k, c in enumerate(chans):
        vals[k % 2, synth_model.channel_index[c]] = 0.5 + 0.5 * k
    b = 1e-2 * rng.standard_normal((3 * cal.n, 2))
    w = np.array([1.0, 2.0])
    p = rng.standard_normal(cal.n_params)
    _assert_gradient_is_the_objectives(cal, p, vals, b, w, rng)


def test_the_evenness_terms_gradient_is_their_objectives(synth_model) -> None:  # type: ignore[no-untyped-def]
    """A pose's lumps (and its smooth part held to a target) joined to the objective
    (`even_over`): the gradient the fit follows is still the objective's."""
    import scipy.sparse as sp

    from sim.face.scan.anchor_fit import AnchorCalibration

    cal = AnchorCalibration(synth_model)
    rng = np.random.default_rng(11)
    chans = list(cal.force_of)[:2]
    vals = np.zeros((1, len(synth_model.channels)))
    vals[0, synth_model.channel_index[chans[0]]] = 1.0
    pose = np.zeros(len(synth_model.channels))
    pose[[synth_model.channel_index[c] for c in chans]] = [0.8, 0.6]
    s = sp.random(60, 3 * cal.n, density=0.02, random_state=3, format="csr")
    cal.even_over(pose, 1e-2 * rng.standard_normal((cal.n, 3)), s, 3.0)
    cal.even_over(pose, np.zeros((cal.n, 3)), s, 2.0, 1e-2 * rng.standard_normal(60))
    b = 1e-2 * rng.standard_normal((3 * cal.n, 1))
    w = np.array([1.0])
    p = rng.standard_normal(cal.n_params)
    _assert_gradient_is_the_objectives(cal, p, vals, b, w, rng)
    bare = AnchorCalibration(synth_model)
    assert cal.objective(p, vals, b, w)[0] > bare.objective(p, vals, b, w)[0]


def test_written_anchors_join_the_channels_field_and_a_rig_without_keeps_its_hash(  # type: ignore[no-untyped-def]
        cal, synth_model, synth_rig, tmp_path) -> None:
    """The fields written to a rig file load back; compiled, each channel's field gains the force
    the fit's linear model used (k_r d) and no other channel changes; a rig without anchors keeps
    its hash and writes no anchor key."""
    import json
    from dataclasses import replace

    from sim.build import compile_model
    from sim.rig import load_rig, save_rig

    p = 0.5 * np.random.default_rng(7).standard_normal(cal.n_params)
    chans = ["zygomaticus_major_l", "zygomaticus_major_r"]
    anchors = {c: np.round(cal.field(c, p), 6) for c in chans}
    save_rig(replace(synth_rig, anchor=anchors), tmp_path / "a.npz")
    back = load_rig(tmp_path / "a.npz")
    assert set(back.anchor) == set(chans) and all(np.array_equal(back.anchor[c], anchors[c]) for c in chans)
    moved = compile_model(back, synth_model.params)
    assert moved.hash != synth_model.hash
    assert compile_model(replace(back, anchor={}), synth_model.params).hash == synth_model.hash
    plain, cols = synth_model.muscle_matrix.toarray(), moved.muscle_matrix.toarray()
    idx = [synth_model.channel_index[c] for c in chans]
    assert np.array_equal(np.delete(cols, idx, axis=1), np.delete(plain, idx, axis=1))
    kr = np.asarray(synth_model.rest_stiffness)
    for c, i in zip(chans, idx):
        want = (kr[:, None] * anchors[c]).ravel()
        assert np.linalg.norm(cols[:, i] - plain[:, i] - want) < 1e-9 * np.linalg.norm(want)
    save_rig(synth_rig, tmp_path / "plain.npz")
    assert "anchor" not in json.loads(str(np.load(tmp_path / "plain.npz")["header"]))


def test_the_sphincters_halves_have_fields_of_their_own_beside_the_whole(cal, synth_model) -> None:  # type: ignore[no-untyped-def]
    """The lips' sphincter and its sided halves (sim.channels.HALVES) are fitted apart: the whole's
    field is not its left half's, each half reaches only its side of the zone (and the blend across
    the midline), and the right half mirrors the left."""
    from sim.face.scan.insertion_fit import mirror_map

    assert {"orbicularis_oris", "orbicularis_oris_l", "orbicularis_oris_r"} <= set(cal.channels)
    rest = np.asarray(synth_model.rest)
    p = np.random.default_rng(3).standard_normal(cal.n_params)
    whole, left, right = (cal.field(c, p) for c in ("orbicularis_oris", "orbicularis_oris_l", "orbicularis_oris_r"))
    on = np.linalg.norm(left, axis=1) > 0
    assert on.sum() > 5 and not np.allclose(whole[on], left[on])
    assert np.all(rest[on, 0] > -0.7)  # the left half reaches the right side only across the blend (1 % at 7 mm)
    mirror = mirror_map(rest)
    zone = np.flatnonzero(np.linalg.norm(right, axis=1) > 0)
    assert np.allclose(right[zone], left[mirror[zone]] * np.array([-1.0, 1.0, 1.0]))


def test_the_foreheads_lumps_leave_out_a_lift_and_find_a_bump() -> None:
    """`forehead_lumps` on the scanned head: the forehead carried up or forward as a whole keeps
    no lump, a bump 5 mm high and 1 cm wide keeps most of its height, and the average with it is
    the lift itself."""
    from sim.face.scan.anchor_fit import forehead_lumps
    from sim.face.scan.rig import scan_model

    model = scan_model()
    s, avg = forehead_lumps(model), forehead_lumps(model, average=True)
    rest = np.asarray(model.rest)
    lift = np.zeros_like(rest)
    lift[:] = [0.0, 0.8, -0.3]
    assert np.abs(s @ lift.ravel()).max() < 1e-9
    assert np.allclose((avg @ lift.ravel()).reshape(-1, 3), lift[0])
    cols = np.unique(s.indices // 3)
    centre = rest[cols[np.argmin(np.abs(rest[cols, 0] - 3.0) + np.abs(rest[cols, 1] - rest[cols, 1].mean()))]]
    bump = np.zeros_like(rest)
    bump[:, 2] = 0.5 * np.exp(-np.sum((rest - centre) ** 2, axis=1) / (2 * 0.25 ** 2))
    lumps = np.linalg.norm((s @ bump.ravel()).reshape(-1, 3), axis=1)
    assert lumps.max() > 0.5 * 0.5


def _assert_gradient_is_the_objectives(cal, p, vals, b, w, rng) -> None:  # type: ignore[no-untyped-def]
    """The fit's gradient against central differences of its objective, on 12 of its nonzero entries."""
    _, grad = cal.objective(p, vals, b, w)
    for i in rng.choice(np.flatnonzero(grad), 12, replace=False):
        h = np.zeros_like(p)
        h[i] = 1e-5
        numeric = (cal.objective(p + h, vals, b, w)[0] - cal.objective(p - h, vals, b, w)[0]) / 2e-5
        assert abs(numeric - grad[i]) < 1e-4 * np.abs(grad).max()
