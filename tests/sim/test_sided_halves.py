"""The lips' sphincter and the mentalis in sided halves (`sim.channels.HALVES`): each half pulls as
its whole channel weighted across the midline, the two together as the whole; the FACS table's
one-sided AU17/23/24 drive a half while the unsided ones keep the whole; on the scanned head
ARKit's one-sided mouthPress settles one-sided, as the scan's does."""

from __future__ import annotations

import numpy as np
import pytest

from sim.build import SkinParams, compile_model, side_weight
from sim.channels import CHANNEL_INDEX, HALVES, channel_spec
from sim.facs import AU_TABLE, EXPRESSIONS


def _column(model, name: str) -> np.ndarray:  # type: ignore[no-untyped-def]
    m = model.muscle_matrix
    m = m.todense() if hasattr(m, "todense") else m
    return np.asarray(m)[:, CHANNEL_INDEX[name]].reshape(-1, 3)


@pytest.fixture(scope="module")
def procedural():  # type: ignore[no-untyped-def]
    from sim.face import default_rig

    return compile_model(default_rig(0), SkinParams(gravity=False))


def test_the_two_halves_pull_as_the_whole(procedural) -> None:  # type: ignore[no-untyped-def]
    for whole in ("orbicularis_oris", "mentalis"):
        f = _column(procedural, whole)
        both = _column(procedural, whole + "_l") + _column(procedural, whole + "_r")
        assert np.abs(f).max() > 0
        assert np.abs(both - f).max() <= 1e-12 * np.abs(f).max(), whole


def test_each_half_pulls_its_own_side(procedural) -> None:  # type: ignore[no-untyped-def]
    x = np.asarray(procedural.rest)[:, 0]  # + is the face's left
    for half, (whole, side) in HALVES.items():
        f = np.sum(_column(procedural, half) ** 2, axis=1)
        own, other = (f[x > 1e-9].sum(), f[x < -1e-9].sum()) if side == "l" else (f[x < -1e-9].sum(), f[x > 1e-9].sum())
        assert other < 0.01 * f.sum() and own > 20 * other, half  # the rest on the midline, half of the whole's
        assert channel_spec(half).kind == "muscle" and channel_spec(whole).kind == "muscle"


def test_the_side_weight_blends_smoothly_across_the_midline(procedural) -> None:  # type: ignore[no-untyped-def]
    rest = np.asarray(procedural.rest)
    left, right = side_weight(procedural.mesh, rest, "l"), side_weight(procedural.mesh, rest, "r")
    assert np.allclose(left + right, 1.0)
    mid = np.abs(rest[:, 0]) < 0.02
    assert np.all(np.abs(left[mid] - 0.5) < 0.05)  # half and half on the midline
    assert np.all(left[rest[:, 0] > 1.0] > 0.99) and np.all(left[rest[:, 0] < -1.0] < 0.01)  # 3 mm wide


def test_one_sided_aus_drive_a_half_and_the_unsided_ones_the_whole() -> None:
    assert AU_TABLE["AU24"] == {"orbicularis_oris": 1.0} and AU_TABLE["AU17"] == {"mentalis": 1.0}
    assert AU_TABLE["AU24_L"] == {"orbicularis_oris_l": 1.0}
    assert AU_TABLE["AU23_R"] == {"orbicularis_oris_r": 0.7}
    assert AU_TABLE["AU17_L"] == {"mentalis_l": 1.0}
    for name, aus in EXPRESSIONS.items():  # the presets drive the whole channels, as before the halves
        for au in aus:
            assert not set(AU_TABLE[au]) & set(HALVES), (name, au)


def _left_share(u: np.ndarray, x: np.ndarray) -> float:
    e = np.sum(u * u, axis=1)
    return float(e[x > 0].sum() / e.sum())


def test_the_scans_one_sided_press_settles_one_sided() -> None:
    """ARKit's mouthPressLeft on the scanned head: the scan presses the left half of the lips (92 %
    of its motion's energy on the face's left); the settled skin does too, mostly, where with one
    sphincter and one chin muscle for both sides it pressed both (half its energy each side but the
    corner's elevator's)."""
    from puppet.capture.arkit_in import shape_channels
    from sim.face.scan.rig import scan_model
    from sim.fit.basis import Settler

    model = scan_model()
    settler = Settler(model)
    x = np.asarray(model.rest)[:, 0]
    shares = {}
    for shape in ("MouthPressLeft", "MouthPressRight"):
        v = shape_channels({shape: np.ones(1)}, 1)[0]
        assert v[CHANNEL_INDEX["orbicularis_oris"]] == 0.0  # the side's half presses, not the whole
        shares[shape] = _left_share(settler.pose(v) - settler.rest, x)
    assert shares["MouthPressLeft"] > 0.75
    assert shares["MouthPressRight"] < 0.25


def test_the_halves_anchors_start_from_the_wholes_split_by_side() -> None:
    """The start of the halves' anchor fit (`anchor_limits.py --halves`): the whole's field split by
    the side's share, whatever halves' fields the rig had, so the command rewrites the same rig."""
    from dataclasses import replace

    from sim.face.scan.anchor_fit import half_anchors
    from sim.face.scan.rig import scan_rig

    rig = scan_rig()
    assert set(HALVES) <= set(rig.anchor)  # the shipped rig carries the halves' fitted fields
    start = half_anchors(rig)
    again = half_anchors(replace(rig, anchor={k: v for k, v in rig.anchor.items() if k not in HALVES}))
    for whole in ("orbicularis_oris", "mentalis"):
        both = start.anchor[whole + "_l"] + start.anchor[whole + "_r"]
        assert np.abs(both - rig.anchor[whole]).max() <= 2e-6
        assert not np.array_equal(start.anchor[whole + "_l"], rig.anchor[whole + "_l"])  # the fitted one replaced
        for half in (whole + "_l", whole + "_r"):
            assert np.array_equal(start.anchor[half], again.anchor[half])
