"""The wrinkle mask on the default face, driven by the real muscles and dynamics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sim.build import compile_model
from sim.channels import MUSCLE_CHANNELS
from sim.facs import apply_au
from sim.integrator import Simulator
from sim.face import default_rig
from sim.state import FaceControl
from sim.wrinkles import AGE_0, apply_wrinkles, default_mask, layer_for
from sim.wrinkles.layer import vertex_normals


@pytest.fixture(scope="module")
def face():
    rig = default_rig(0)
    if not rig.wrinkles:
        rig = dataclasses.replace(rig, wrinkles=default_mask(rig.mesh))
    model = compile_model(rig)
    return model, Simulator(model)


def _settled(face, channels: dict[str, float]):
    model, sim = face
    state = model.rest_state()
    control = FaceControl(model)
    for name, value in channels.items():
        control.set(name, value)
    sim.settle(state, control, max_seconds=2.0)
    return state


def _swap_side(name: str) -> str:
    if name.endswith("_l"):
        return name[:-2] + "_r"
    if name.endswith("_r"):
        return name[:-2] + "_l"
    return name


def test_mask_lines_name_real_channels_and_mirror(face) -> None:
    model, _ = face
    lines = {ln.name: ln for ln in model.rig.wrinkles}
    assert len(lines) >= 20
    for ln in lines.values():
        assert ln.muscles and set(ln.muscles) <= set(MUSCLE_CHANNELS), ln.name
    for name, ln in lines.items():
        if name.endswith("_l") and name[:-2] + "_r" in lines:
            other = lines[name[:-2] + "_r"]
            mirrored = ln.points * [-1.0, 1.0]
            np.testing.assert_allclose(other.points, mirrored, atol=1e-9)
            assert {_swap_side(m) for m in ln.muscles} == set(other.muscles)
    kinds = {"forehead", "glabella_vertical", "glabella_oblique", "nasal_root", "crows_foot",
             "lower_lid", "nasolabial", "marionette", "lip_upper", "lip_lower", "chin_crease"}
    assert all(any(n.startswith(k) for n in lines) for k in kinds)


def test_every_main_line_has_vertices_on_every_resolution() -> None:
    for res in (0, 1):
        rig = default_rig(res)
        lines = default_mask(rig.mesh)
        from sim.wrinkles import compile_wrinkles

        layer = compile_wrinkles(rig.mesh.vertices, rig.mesh.triangles, lines)
        counts = dict(zip(layer.line_names, (len(v) for v in layer.line_vertices)))
        for name, n in counts.items():
            if not name.startswith(("lip_", "glabella_oblique")):
                assert n >= 3, (res, name, n)


def test_no_bulge_at_rest_or_below_age_0(face) -> None:
    model, _ = face
    state = model.rest_state()
    state.age = 90.0
    apply_wrinkles(model, state)
    np.testing.assert_array_equal(state.surface, state.positions)
    frown = _settled(face, {"corrugator_l": 1, "corrugator_r": 1, "procerus": 1})
    frown.age = AGE_0 - 1
    apply_wrinkles(model, frown)
    np.testing.assert_array_equal(frown.surface, frown.positions)


GROUPS = {
    "forehead_2": ("frontalis_inner_l", "frontalis_inner_r", "frontalis_outer_l", "frontalis_outer_r"),
    "glabella_vertical_l": ("corrugator_l", "corrugator_r", "procerus"),
    "nasolabial_l": ("levator_labii_l", "zygomaticus_major_l"),
    "chin_crease": ("mentalis",),
    "crows_foot_middle_l": ("orbicularis_oculi_l",),
    "marionette_l": ("depressor_anguli_oris_l",),
}


@pytest.mark.parametrize("line", sorted(GROUPS))
def test_a_line_bulges_when_its_own_muscles_contract(face, line: str) -> None:
    model, _ = face
    channels = GROUPS[line]
    lines = {ln.name: ln for ln in model.rig.wrinkles}
    assert set(channels) <= set(lines[line].muscles)
    state = _settled(face, {c: 1.0 for c in channels})
    layer = layer_for(model)
    verts = layer.line_vertices[layer.line_names.index(line)]
    young = np.linalg.norm(layer.displacement(state.positions, 30.0)[verts], axis=1).max()
    old = np.linalg.norm(layer.displacement(state.positions, 75.0)[verts], axis=1).max()
    assert young == 0.0
    assert old > 0.02, old  # cm


def _crease_depth(model, surface: np.ndarray, region: np.ndarray, radius: float = 0.4) -> float:
    """Deepest groove in a region: for each vertex, how far the skin within `radius` (rest cm)
    rises above it along its normal, on average. Pure geometry of the drawn surface."""
    rest = model.rest
    tree = cKDTree(rest)
    n = vertex_normals(surface, model.triangles)
    depths = [
        np.mean((surface[tree.query_ball_point(rest[i], radius)] - surface[i]) @ n[i])
        for i in np.flatnonzero(region)
    ]
    return float(max(depths))


def test_frown_creases_the_glabella_deeper_at_75_than_at_30(face) -> None:
    model, _ = face
    frown = _settled(face, {"corrugator_l": 1, "corrugator_r": 1, "procerus": 1})
    region = model.rig.mesh.regions["glabella"]
    depth = {}
    for age in (30.0, 75.0):
        frown.age = age
        apply_wrinkles(model, frown)
        depth[age] = _crease_depth(model, frown.surface, region)
    assert depth[75.0] > depth[30.0] + 0.015, depth  # at least 0.15 mm deeper


def test_simulator_step_draws_the_bulges_from_the_age_channel(face) -> None:
    model, sim = face
    for age, expect_bulge in ((30.0, False), (75.0, True)):
        state = model.rest_state()
        control = FaceControl(model)
        apply_au(control, "AU4", 1.0)
        control.set("age", age)
        sim.settle(state, control, max_seconds=2.0)
        assert state.age == age
        moved = np.linalg.norm(state.surface - state.positions, axis=1).max()
        assert (moved > 0.02) == expect_bulge, (age, moved)


def test_aged_skin_is_softer_and_stiffens_later() -> None:
    from sim.wrinkles import skin_params_for_age

    young = [skin_params_for_age(a, 0.15) for a in (0, 20, 30, AGE_0)]
    assert all(p.k_low_scale == 1.0 and p.strain_threshold == 0.15 for p in young)
    old = [skin_params_for_age(a, 0.15) for a in (45, 60, 75, 90)]
    assert all(b.k_low_scale < a.k_low_scale for a, b in zip(old, old[1:]))
    assert all(b.strain_threshold > a.strain_threshold for a, b in zip(old, old[1:]))
    assert all(p.k_high_scale <= 1.0 for p in old)  # never shortens the stable step


def test_aged_face_deforms_more_under_the_same_frown(face) -> None:
    model, sim = face
    travel = {}
    for age in (30.0, 85.0):
        state = model.rest_state()
        control = FaceControl(model)
        apply_au(control, "AU4", 1.0)
        control.set("age", age)
        sim.settle(state, control, max_seconds=2.0)
        travel[age] = np.linalg.norm(state.positions - model.rest, axis=1).max()
    assert travel[85.0] > travel[30.0] * 1.02, travel
    assert not sim.guard_events


def test_rig_file_keeps_the_wrinkle_lines(tmp_path, face) -> None:
    from sim.rig import load_rig, save_rig

    model, _ = face
    path = tmp_path / "face.rig.npz"
    save_rig(model.rig, path)
    back = load_rig(path)
    assert [w.name for w in back.wrinkles] == [w.name for w in model.rig.wrinkles]
    for a, b in zip(back.wrinkles, model.rig.wrinkles):
        np.testing.assert_allclose(a.points, b.points)
        assert (a.muscles, a.width_minus, a.width_plus, a.asym_plus, a.emphasis) == (
            b.muscles, b.width_minus, b.width_plus, b.asym_plus, b.emphasis)


def test_puppet_pose_age_75_creases_the_frown_deeper(tmp_path, face) -> None:
    from puppet.cli import main

    model, _ = face
    depth = {}
    for age in (30, 75):
        out = tmp_path / f"frown_{age}.npz"
        assert main(["pose", "--au", "AU4=1", "--age", str(age), "--seconds", "1.5", "--out", str(out)]) == 0
        surface = np.load(out)["surface"]
        depth[age] = _crease_depth(model, surface, model.rig.mesh.regions["glabella"])
    assert depth[75] > depth[30] + 0.015, depth


def test_compiled_frame_matches_the_numpy_reference_on_the_face(face) -> None:
    from sim.wrinkles.layer import compiled_displacement, wrinkle_displacement

    model, _ = face
    state = _settled(face, {"corrugator_l": 1, "corrugator_r": 1, "procerus": 1,
                            "zygomaticus_major_l": 1, "zygomaticus_major_r": 1, "mentalis": 0.7})
    layer = layer_for(model)
    ref = wrinkle_displacement(layer, state.positions, 80.0)
    assert np.abs(ref).max() > 0.05
    np.testing.assert_allclose(compiled_displacement(layer, state.positions, 80.0), ref, rtol=1e-9, atol=1e-12)
