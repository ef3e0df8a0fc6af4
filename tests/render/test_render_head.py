"""The default face renders as a head: skin and hair above the mask's hairline, ears at the sides,
a neck below the chin; a rig that is not the default face is drawn without them."""

from __future__ import annotations

import dataclasses

import numpy as np

from render.offscreen import OffscreenRenderer
from sim.build import compile_model
from sim.face import default_rig


def _covered(img: np.ndarray) -> np.ndarray:
    """Pixels that differ from the background (the corner pixel is background)."""
    return np.abs(img.astype(float) - img[0, 0]).sum(axis=2) > 12


def test_head_around_the_face(gl) -> None:
    rig = default_rig(0)
    with_head = compile_model(rig)
    mask_only = compile_model(dataclasses.replace(rig, name="mask"))
    shots = {}
    for name, model in (("head", with_head), ("mask", mask_only)):
        with OffscreenRenderer(model, (320, 320), ctx=gl) as off:
            off.renderer.camera.fit(np.array([-9.0, -24.0, -20.0]), np.array([9.0, 12.0, 3.0]))
            st = model.rest_state()
            img = off.render_frame(st, record=False)
            top = off.renderer.project(np.array([[0.0, 10.3, -9.0]]), (320, 320))[0]  # the vertex, over the ears
            neck = off.renderer.project(np.array([[0.0, -18.0, -4.0]]), (320, 320))[0]
            cov = _covered(img)
            hits = [bool(cov[int(p[1]), int(p[0])]) for p in (top, neck)]
            off.renderer.camera.yaw = 0.5 * np.pi  # from the face's left: the ear, behind the mask
            side = _covered(off.render_frame(st, record=False))
            ear = off.renderer.project(np.array([[7.6, -2.3, -9.4]]), (320, 320))[0]
            assert gl.error == "GL_NO_ERROR"
        shots[name] = hits + [bool(side[int(ear[1]), int(ear[0])])]
    assert shots["head"] == [True, True, True]  # crown, neck, ear drawn
    assert shots["mask"] == [False, False, False]  # nothing there without the head
