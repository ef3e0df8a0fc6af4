"""The lids drawn over the eyeballs they close on (sim.face.scan.lid_contact): where anger's narrowed
lids sank into the cornea (the cornea's outline then showed as the margin: an upper margin peaking
over the iris, an uneven lower one) the drawn margins lie on the eyeball's front, the lashes with
them; lids that do not sink are drawn exactly as simulated. Exports of the scan lay them the same
way: tests/puppet/test_pup_export_lids.py."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.scan.data import PARTS, SCLERA


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    from puppet.face_cache import scan_model
    from render.scan_draw import ScanPoser
    from sim.face.scan.blendshapes import StateControl
    from sim.face.scan.dressing import dressing_for
    from sim.facs import apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    poser = ScanPoser(dressing_for(model))
    sim, state = Simulator(model, wrinkles=False), model.rest_state()
    c = FaceControl(model)
    apply_expression(c, "anger", 1.0, preset_face(model.rig))
    sim.settle(state, c, max_seconds=2.0)
    posed = poser.dressing.pose(np.asarray(state.surface), StateControl(state))
    return model, poser, posed


def _depth(posed: np.ndarray, centre: np.ndarray, side: str, points: np.ndarray) -> np.ndarray:
    """(P,) mm each point lies outside the posed eyeball's outer shell (negative: inside it): its
    distance from the centre against where the ray from the centre through it leaves the shell."""
    from sim.face.scan.data import scan_data

    lo, _ = PARTS[f"eyeball_{side}"]
    tri = scan_data().triangles(f"eyeball_{side}")
    tri = tri[(tri < lo + SCLERA).all(axis=1)]
    a, b, c = (posed[tri[:, k]].astype(np.float64) - centre for k in range(3))
    e1, e2 = b - a, c - a
    out = []
    for p in points.astype(np.float64) - centre:
        d = p / np.linalg.norm(p)
        h = np.cross(d, e2)
        det = (e1 * h).sum(axis=1)
        ok = np.abs(det) > 1e-12
        f = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = -a
        u = f * (s * h).sum(axis=1)
        q = np.cross(s, e1)
        v = f * (q @ d)
        t = f * (e2 * q).sum(axis=1)
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out.append(10.0 * (np.linalg.norm(p) - t[hit].max()) if hit.any() else np.inf)
    return np.array(out)


def test_nothing_moves_while_the_lids_rest_on_the_eyes(scene) -> None:  # type: ignore[no-untyped-def]
    from sim.face.scan.blendshapes import StateControl

    model, poser, _ = scene
    rest = model.rest_state()
    posed = poser.dressing.pose(np.asarray(rest.surface), StateControl(rest))
    assert np.array_equal(poser.contact.press(posed.copy()), posed)


def test_angers_narrowed_lids_are_drawn_over_the_cornea(scene) -> None:  # type: ignore[no-untyped-def]
    """As simulated, anger's margins sink more than a millimetre into the drawn eyeball; drawn, none
    lies deeper in it than at rest (the corners) by more than 0.2 mm (the contact reads the front off
    its radius by the angle from the axis, within 0.15 mm of the shell),
    and the lashes hanging from them moved out with them."""
    model, poser, posed = scene
    drawn = poser.contact.press(posed.copy())
    rest = poser.look.rest
    for k, (side, (upper, lower)) in enumerate(zip("lr", poser.look.lids)):
        centre = poser.dressing.eye_centres[k]
        margin = np.concatenate([upper[1:-1], lower[1:-1]])
        at_rest = np.minimum(_depth(rest, centre, side, rest[margin]), 0.0)
        assert (_depth(posed, centre, side, posed[margin]) - at_rest).min() < -1.0
        assert (_depth(drawn, centre, side, drawn[margin]) - at_rest).min() > -0.2
        lo, hi = PARTS[f"eyelashes_{side}"]
        moved = np.linalg.norm(drawn[lo:hi] - posed[lo:hi], axis=1)
        assert moved.max() > 0.1  # cm
    # only the lids, their things and backs, around the eyes
    changed = np.flatnonzero((drawn != posed).any(axis=1))
    centres = poser.dressing.eye_centres
    assert np.linalg.norm(drawn[changed, None] - centres[None], axis=2).min(axis=1).max() < 3.0  # cm: the outer lashes reach 2.7


def test_no_eyeball_shows_beyond_the_drawn_margins(scene) -> None:  # type: ignore[no-untyped-def]
    """Seen from the front, no part of the eyeball shows above anger's drawn upper margin or below
    its lower one (as simulated, the cornea stood out through the lids: its outline peaked 1-2 mm
    above the upper margin over the iris, and showed below the lower one)."""
    model, poser, posed = scene
    drawn = poser.contact.press(posed.copy())
    before, after = _beyond_margins(poser, posed), _beyond_margins(poser, drawn)
    assert max(before) > 1.0, before
    assert max(after) < 0.2, after


def _beyond_margins(poser, posed: np.ndarray) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """mm: how far the left eyeball's vertices that show in an orthographic front view (no skin
    triangle covering them in front) lie above the upper margin and below the lower one at their x,
    at most, over the middle two thirds of the eye."""
    upper, lower = poser.look.lids[0]
    lo, _ = PARTS["eyeball_l"]
    ball = posed[lo:lo + SCLERA].astype(np.float64)
    x0, x1 = sorted((float(posed[upper[0], 0]), float(posed[upper[-1], 0])))
    span = x1 - x0
    ball = ball[(ball[:, 0] > x0 + span / 6) & (ball[:, 0] < x1 - span / 6) & (ball[:, 2] > poser.dressing.eye_centres[0, 2])]
    tri = posed[poser.look.groups["skin"]].astype(np.float64)
    tri = tri[np.linalg.norm(tri.mean(axis=1)[:, :2] - poser.dressing.eye_centres[0, :2], axis=1) < 2.2]
    shown = ball[[not _covered(tri, p) for p in ball]]
    up = np.interp(shown[:, 0], *_by_x(posed[upper]))
    down = np.interp(shown[:, 0], *_by_x(posed[lower]))
    return float(10.0 * (shown[:, 1] - up).max()), float(10.0 * (down - shown[:, 1]).max())


def _by_x(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(p[:, 0])
    return p[order, 0].astype(np.float64), p[order, 1].astype(np.float64)


def _covered(tri: np.ndarray, p: np.ndarray) -> bool:
    """Whether a triangle (T,3,3) covers p in the front view (x, y) and lies in front of it (z)."""
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    v0, v1, v2 = b - a, c - a, p[:2] - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    ok = np.abs(den) > 1e-14
    v = np.where(ok, (d11 * d20 - d01 * d21) / np.where(ok, den, 1.0), -1.0)
    w = np.where(ok, (d00 * d21 - d01 * d20) / np.where(ok, den, 1.0), -1.0)
    inside = (v >= 0) & (w >= 0) & (v + w <= 1)
    if not inside.any():
        return False
    z = tri[inside, 0, 2] + v[inside] * (tri[inside, 1, 2] - tri[inside, 0, 2]) + w[inside] * (tri[inside, 2, 2] - tri[inside, 0, 2])
    return bool((z > p[2]).any())


def test_the_compiled_press_is_the_numpy_steps_to_the_bit(scene) -> None:  # type: ignore[no-untyped-def]
    model, poser, posed = scene
    kernel = poser.contact.press(posed.copy())
    steps = poser.contact.press_steps(posed.copy())
    assert not np.array_equal(kernel, posed)  # anger's lids sank: something moved
    assert np.array_equal(kernel, steps)
