"""The closing lids' seam on the scanned head (render.scan_seam): the skin at the margins is drawn
in shadow as the lids close (a blink's seam a dark line, not the pale fleck of the lower lid's margin
turned up to the light), the eyeball of a shut eye too (not a brown fleck of iris where the margins
do not quite meet), and nothing while the eyes are open."""

from __future__ import annotations

import numpy as np
import pytest

from render.scan_look import ScanLook
from render.scan_seam import LidSeam
from sim.face.scan.blendshapes import ScanShapes
from sim.face.scan.data import scan_data


@pytest.fixture(scope="module")
def seam() -> LidSeam:
    from puppet.face_cache import scan_model
    from sim.face.scan.dressing import eye_margins

    return LidSeam(ScanLook(scan_data().neutral, eye_margins(scan_model(None).mesh)))


def test_the_seam_lies_along_the_simulated_meshs_eye_openings(seam: LidSeam) -> None:
    """Each eye's two margins are its eye loop of the simulated mesh split at the corner landmarks:
    together the whole loop, meeting at the corners, the upper above the lower, each running from
    the inner corner (nearer the nose) to the outer; and a look without them is refused."""
    from puppet.face_cache import scan_model
    from sim.face.scan.anatomy import skin_layout
    from sim.face.scan.data import PARTS

    mesh = scan_model(None).mesh
    skin, rest = skin_layout().vertices, scan_data().neutral
    for k, (side, (upper, lower)) in enumerate(zip("lr", seam.lids)):
        assert set(upper) | set(lower) == set(skin[mesh.eye_loops[k]])
        assert len(upper) + len(lower) == len(mesh.eye_loops[k]) + 2  # the corners in both
        for lid in (upper, lower):
            assert (lid[0], lid[-1]) == tuple(skin[mesh.landmarks[f"eye_{c}_{side}"]] for c in ("inner", "outer"))
        assert rest[upper[1:-1], 1].min() > rest[lower[1:-1], 1].max() - 0.3
        assert rest[upper[1:-1], 1].mean() > rest[lower[1:-1], 1].mean()
        assert abs(rest[upper[0], 0]) < abs(rest[upper[-1], 0])
        assert seam.balls[k] == PARTS[f"eyeball_{side}"]
    with pytest.raises(ValueError, match="lid margins"):
        LidSeam(ScanLook(scan_data().neutral))


def _middle(seam: LidSeam, eye: int) -> np.ndarray:
    """The margin vertices (upper then lower, as `shadow` lists them) over the middle half of the eye."""
    upper, lower = seam.lids[eye]
    chain = np.concatenate([upper, lower])
    x = scan_data().neutral[chain, 0]
    lo, hi = x.min(), x.max()
    return (x > lo + 0.25 * (hi - lo)) & (x < hi - 0.25 * (hi - lo))


def test_no_shadow_with_the_eyes_open(seam: LidSeam) -> None:
    rest = scan_data().neutral.astype(np.float32)
    for s in seam.shadow(rest):
        assert s.max() == 0.0
    rows = np.zeros((len(rest), 7), np.float32)
    rows[:, :3] = rest
    assert not seam.shade(rows)[:, 6].any()  # nor the eyeballs
    wide = ScanShapes(None, {"eyeWide_L": 1.0, "eyeWide_R": 1.0}).positions
    assert max(s.max() for s in seam.shadow(wide)) == 0.0


def test_the_scans_own_blink_is_shaded_at_its_seam_only(seam: LidSeam) -> None:
    """The scan's eyeBlink_L shuts the left eye (on +x): its margins shaded across the middle and its
    eyeball darkened, the open right eye not at all, and the skin beyond BAND of the margins
    untouched."""
    closed = ScanShapes(None, {"eyeBlink_L": 1.0}).positions
    left = int(np.argmax([scan_data().neutral[np.concatenate(lids), 0].mean() for lids in seam.lids]))
    shadow = seam.shadow(closed)
    assert shadow[left][_middle(seam, left)].min() > 0.9
    assert shadow[1 - left].max() == 0.0
    rows = np.zeros((len(closed), 7), np.float32)
    rows[:, :3] = closed
    seam.shade(rows)
    (lo, hi), (lo_open, hi_open) = seam.balls[left], seam.balls[1 - left]
    assert (rows[lo:hi, 6] == 1.0).all()  # the shut eye's eyeball in the lids' shadow
    assert not rows[lo_open:hi_open, 6].any()
    rows[lo:hi, 6] = 0.0
    darkened = np.flatnonzero(rows[:, 6] > 0.0)
    assert np.isin(darkened, seam.band[left]).all()
    assert rows[:, 6].max() > 1.0  # the key light shaded too (render.scan_shaders)


def test_a_simulated_blink_is_drawn_with_its_seam_in_shadow() -> None:
    """The drawing's rows of the simulated head closed by AU45 carry the shadow (a fold term past 1
    on the lower lid's margin across the middle of each eye), where the open eye's carry none."""
    from puppet.face_cache import scan_model
    from render.scan_draw import ScanPoser
    from sim.face.scan.dressing import dressing_for
    from sim.facs import apply_au
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    poser = ScanPoser(dressing_for(model))
    sim, state = Simulator(model, wrinkles=False), model.rest_state()
    c = FaceControl(model)
    apply_au(c, "AU45", 1.0)
    sim.settle(state, c, max_seconds=2.0)
    shut = poser.rows(state).copy()
    rest = poser.rows(model.rest_state()).copy()
    seam = poser.seam
    assert rest[np.concatenate(seam.band), 6].max() < 0.5
    for eye, (upper, lower) in enumerate(seam.lids):
        middle = _middle(seam, eye)[len(upper):]
        at = np.isin(seam.band[eye], lower[middle])  # the lower margin's own vertices, the middle half
        assert at.any()
        assert np.median(shut[seam.band[eye][at], 6]) > 1.0


def test_a_closed_lids_seam_is_drawn_no_paler_than_the_lid(gl) -> None:  # type: ignore[no-untyped-def]
    """The simulated blink drawn: in the box on screen around each closed eye's margins, few pixels
    are as pale as the closed upper lid 5-8 mm above them (5-7 %; without the seam's shadow 25-28 %:
    where the upper margin stays 0.4-1.9 mm above the lower one, the lower lid's upturned margin
    showed as a pale fleck between the seam and the lashes)."""
    from puppet.face_cache import scan_model
    from render.offscreen import OffscreenRenderer
    from sim.facs import apply_au
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    sim, state = Simulator(model, wrinkles=False), model.rest_state()
    c = FaceControl(model)
    apply_au(c, "AU45", 1.0)
    sim.settle(state, c, max_seconds=2.0)
    size = (600, 400)
    with OffscreenRenderer(model, size, ctx=gl) as off:
        off.renderer.camera.scale = 0.3  # the eyes and the brows
        img = off.render_frame(state, record=False).astype(float) @ np.array([0.299, 0.587, 0.114])
        from render.scan_draw import ScanPoser
        from sim.face.scan.dressing import dressing_for

        poser = ScanPoser(dressing_for(model))
        seam, rows = poser.seam, poser.rows(state)
        rest = scan_data().neutral
        for eye, (upper, lower) in enumerate(seam.lids):
            chain = np.concatenate([upper, lower])
            xy = off.renderer.project(rows[chain, :3], size)
            x0, y0 = np.floor(xy.min(axis=0)).astype(int) - 2
            x1, y1 = np.ceil(xy.max(axis=0)).astype(int) + 2
            seam_px = img[y0:y1 + 1, x0:x1 + 1]
            c = rest[chain].mean(axis=0)
            lid = np.flatnonzero((np.abs(rest[:, 0] - c[0]) < 0.4) & (rest[:, 1] > rest[upper, 1].max() + 0.5)
                                 & (rest[:, 1] < rest[upper, 1].max() + 0.8) & (rest[:, 2] > c[2] - 0.5))
            lxy = np.round(off.renderer.project(rows[lid, :3], size)).astype(int)
            lid_lum = float(np.median(img[lxy[:, 1], lxy[:, 0]]))
            assert (seam_px > 0.9 * lid_lum).mean() < 0.15, (eye, float((seam_px > 0.9 * lid_lum).mean()))
