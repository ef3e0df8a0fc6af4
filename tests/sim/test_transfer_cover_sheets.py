"""A carried sheet muscle made to cover the skin its reference pulls on (sim.face.transfer.carry.
cover_sheet): the frontalis' inner and outer parts, carried askew, left a strip of forehead between
them that neither pulled, and an imported head's mid-brow rose half as far as the reference's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim.face.transfer.carry import SurfaceMap, cover_sheet
from sim.model import SheetMuscle
from sim.muscles import sheet_direction, sheet_falloff, sheet_length_ratio, sheet_length_ratio_limit, sheet_zone


@pytest.fixture(scope="module")
def face():
    from sim.face import default_rig

    return default_rig(0)


def _pull(m: SheetMuscle, x: np.ndarray) -> np.ndarray:
    return sheet_falloff(sheet_length_ratio(m, x), m.eta, sheet_length_ratio_limit(m)) * sheet_zone(m, x)


def _same_skin(face) -> SurfaceMap:
    v = np.asarray(face.mesh.vertices, float)
    return SurfaceMap(v, np.asarray(face.mesh.triangles), v.copy())


def test_a_sheet_already_covering_its_skin_is_left_alone(face) -> None:
    smap = _same_skin(face)
    for ch in ("frontalis_inner_l", "frontalis_outer_r", "mentalis"):
        (m,) = face.muscles[ch]
        out = cover_sheet(smap, m, m)
        for key in ("attach1", "attach2", "insert1", "insert2"):
            assert np.allclose(getattr(out, key), getattr(m, key)), (ch, key)
        assert out.width == pytest.approx(m.width)


def test_a_sheet_slid_aside_and_narrowed_covers_its_skin_again(face) -> None:
    """The carried rectangle lies 1 cm to one side and is 40 % narrower: after covering, every
    vertex the reference pulls on with at least a quarter of its peak is pulled again, with the
    same direction and the same length ratio (eqs 19, 21) everywhere."""
    smap = _same_skin(face)
    x = smap.new_vertices
    (ref,) = face.muscles["frontalis_inner_l"]
    t = (ref.attach2 - ref.attach1) / np.linalg.norm(ref.attach2 - ref.attach1)
    aside = dataclasses.replace(ref, attach1=ref.attach1 + t, attach2=ref.attach2 + t, insert1=ref.insert1 + t,
                                insert2=ref.insert2 + t, width=0.6 * ref.width)
    strong = _pull(ref, x) >= 0.25 * _pull(ref, x).max()
    assert (_pull(aside, x)[strong] == 0).sum() > 10  # the strip left unpulled
    out = cover_sheet(smap, ref, aside)
    assert (_pull(out, x)[strong] > 0).all()
    assert np.allclose(sheet_direction(out), sheet_direction(ref))
    assert np.allclose(sheet_length_ratio(out, x), sheet_length_ratio(ref, x))
    assert out.width >= aside.width


def test_imported_frontalis_pulls_the_mid_brow_skin(face) -> None:
    """On the default face carried onto a stretched, re-meshed copy of itself with cover_sheets,
    the skin under each mid-brow landmark is inside a frontalis part's zone, as on the reference."""
    from scipy.spatial.transform import Rotation

    from sim.face.builder import build_face_mesh
    from sim.face.transfer import TransferOptions, from_arrays, parse_landmarks, transfer_rig

    affine = 10.0 * Rotation.from_euler("xyz", [10, -20, 5], degrees=True).as_matrix() @ np.diag([1.2, 0.9, 1.15])
    target = build_face_mesh(1)
    head = from_arrays(target.vertices @ affine.T, target.triangles, "head.obj")
    lms = parse_landmarks({k: int(i) for k, i in target.landmarks.items()}, "head.json")
    rig = transfer_rig(face, head, lms, name="head", options=TransferOptions(cover_sheets=True)).rig
    for side in "lr":
        brow = np.asarray(rig.mesh.vertices)[rig.mesh.landmarks[f"brow_mid_{side}"]][None]
        parts = [m for part in ("inner", "outer") for m in rig.muscles[f"frontalis_{part}_{side}"]]
        pulled = sum(float(_pull(m, brow)[0]) for m in parts)
        assert pulled > 0.25, side


def test_matched_forces_pull_as_hard_in_all_as_the_reference(face) -> None:
    """A head twice the reference's size with its forehead stretched: after match_forces every
    channel whose total force over the free skin, for the face's area, fell short of the
    reference's has the reference's (within the factor's limits), where the carried muscles alone
    differ; a channel whose zone covers more skin than the reference's keeps its force (its
    density is the reference's)."""
    from sim.face.builder import build_face_mesh
    from sim.face.transfer import TransferOptions, from_arrays, parse_landmarks, transfer_rig
    from sim.face.transfer.forces import LIMITS, channel_totals

    target = build_face_mesh(1)
    v = np.asarray(target.vertices, float) * 2.0
    v[:, 1] += 0.4 * np.clip(v[:, 1] - v[target.landmarks["glabella"], 1], 0.0, None)
    head = from_arrays(v, target.triangles, "head.obj")
    lms = parse_landmarks({k: int(i) for k, i in target.landmarks.items()}, "head.json")
    plain = transfer_rig(face, head, lms, name="head").rig
    matched = transfer_rig(face, head, lms, name="head", options=TransferOptions(match_forces=True)).rig
    want, before, after = channel_totals(face), channel_totals(plain), channel_totals(matched)
    assert max(abs(before[ch] / want[ch] - 1) for ch in want if want[ch] > 0) > 0.1
    stronger = [ch for ch, total in want.items() if 0 < total and LIMITS[0] < total / before[ch] < LIMITS[1]]
    kept = [ch for ch, total in want.items() if 0 < total < before[ch]]
    assert stronger and kept  # the stretched head has zones covering less skin and zones covering more
    for ch in stronger:
        assert after[ch] == pytest.approx(want[ch], rel=1e-6), ch
    for ch in kept:
        assert after[ch] == pytest.approx(before[ch], rel=1e-6), ch
