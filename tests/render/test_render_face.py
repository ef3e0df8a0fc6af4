"""The shaded face on Mesa's software rasterizer: framed, shaded, expressive, eyes that look around
and hide behind the lids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from render_faces import Faces, skin_mask, with_eyes

from render.offscreen import OffscreenRenderer, render_to_file


def _box(img: np.ndarray, xy: np.ndarray, r: int) -> np.ndarray:
    x, y = int(round(xy[0])), int(round(xy[1]))
    return img[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1].astype(float)


def test_face_fills_a_sensible_share_of_the_frame_and_is_shaded(offscreen: OffscreenRenderer,
                                                                faces: Faces) -> None:
    img = offscreen.render_frame(faces.rest)
    skin = skin_mask(img)
    assert 0.15 < skin.mean() < 0.8
    ys, xs = np.nonzero(skin)
    h, w = skin.shape
    assert abs(xs.mean() - w / 2) < 0.1 * w and abs(ys.mean() - h / 2) < 0.15 * h
    lum = img[skin].astype(float) @ [0.299, 0.587, 0.114]
    assert lum.std() > 12  # lit, not flat
    corner = img[:5, :5].astype(float)
    assert np.ptp(corner.reshape(-1, 3).mean(axis=0)) < 12  # neutral (grey) background


def test_expression_changes_the_mouth_far_more_than_the_forehead(offscreen: OffscreenRenderer,
                                                                 faces: Faces) -> None:
    a = offscreen.render_frame(faces.rest).astype(float)
    b = offscreen.render_frame(faces.happy).astype(float)
    mesh = faces.model.mesh
    size = (a.shape[1], a.shape[0])
    loop = offscreen.renderer.project(faces.model.rest[mesh.mouth_loop], size)
    mouth = loop.mean(axis=0)
    r = int(np.ptp(loop[:, 0]) * 0.6)  # a box as wide as the mouth and its corners
    eyes = mesh.eye_centers.mean(axis=0)
    brow_to_mouth = eyes - faces.model.rest[mesh.mouth_loop].mean(axis=0)
    forehead = offscreen.renderer.project(eyes + 0.9 * brow_to_mouth, size)[0]  # above the brows
    d_mouth = np.abs(_box(a, mouth, r) - _box(b, mouth, r)).mean()
    d_forehead = np.abs(_box(a, forehead, r // 2) - _box(b, forehead, r // 2)).mean()
    assert d_mouth > 2.5, (d_mouth, d_forehead)
    assert d_mouth > 5 * d_forehead


def _pupil(off: OffscreenRenderer, faces: Faces, state: object, eye: int) -> tuple[float, int]:
    """Centroid x and count of near-black (pupil) pixels over one eyeball's projected disc."""
    img = off.render_frame(state).astype(float)
    size = (img.shape[1], img.shape[0])
    mesh = faces.model.mesh
    c = off.renderer.project(mesh.eye_centers[eye], size)[0]
    edge = off.renderer.project(mesh.eye_centers[eye] + [mesh.eye_radius, 0.0, 0.0], size)[0]
    r = np.linalg.norm(edge - c)
    ys, xs = np.mgrid[: size[1], : size[0]]
    disc = (xs - c[0]) ** 2 + (ys - c[1]) ** 2 < r**2
    dark = disc & (img @ [0.299, 0.587, 0.114] < 40)
    return (float(xs[dark].mean()) if dark.any() else float("nan")), int(dark.sum())


def test_eyes_follow_eyes_yaw(gl, faces: Faces) -> None:
    with OffscreenRenderer(faces.model, (640, 480), ctx=gl) as off:
        left, n_left = _pupil(off, faces, with_eyes(faces.rest, yaw=-1.0), 0)
        right, n_right = _pupil(off, faces, with_eyes(faces.rest, yaw=1.0), 0)
    assert n_left > 15 and n_right > 15
    # +yaw turns the gaze towards the face's own left (+X), which is image right in the front view
    assert right - left > 4.0


def _blink(faces: Faces) -> object:
    """The face with both lids closed by the simulation (orbicularis oculi, lid part, fully on)."""
    from sim.integrator import Simulator
    from sim.state import FaceControl

    control = FaceControl(faces.model)
    for side in ("l", "r"):
        control.set(f"orbicularis_oculi_lid_{side}", 1.0)
    closed = faces.rest.copy()
    Simulator(faces.model).settle(closed, control)
    return closed


def test_closed_lids_hide_the_eyes(gl, faces: Faces) -> None:
    closed = _blink(faces)
    with OffscreenRenderer(faces.model, (640, 480), ctx=gl) as off:
        for eye in (0, 1):
            _, n_open = _pupil(off, faces, faces.rest, eye)
            _, n_closed = _pupil(off, faces, closed, eye)
            assert n_open > 15
            assert n_closed < 0.1 * n_open, (eye, n_open, n_closed)


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_render_to_file_writes_an_image_of_the_size_asked(gl, faces: Faces, tmp_path: Path,
                                                          suffix: str) -> None:
    from PIL import Image

    out = render_to_file(faces.model, faces.happy, tmp_path / f"face{suffix}", size=(96, 64), ctx=gl)
    with Image.open(out) as im:
        assert im.size == (96, 64)
        assert skin_mask(np.asarray(im.convert("RGB"))).mean() > 0.1


def test_render_to_file_rejects_unknown_suffix(gl, faces: Faces, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="png"):
        render_to_file(faces.model, faces.rest, tmp_path / "face.bmpx", size=(32, 32), ctx=gl)


def test_supersampling_smooths_the_silhouette(gl, faces: Faces) -> None:
    """More distinct grey levels along edges when 2x2 samples are averaged than without any AA."""
    with OffscreenRenderer(faces.model, (160, 120), ctx=gl) as off:
        off.renderer.antialias = "none"
        hard = off.render_frame(faces.rest)
        off.renderer.supersample = 2
        soft = off.render_frame(faces.rest)
    edge = skin_mask(hard) ^ np.roll(skin_mask(hard), 1, axis=1)
    assert np.abs(hard.astype(int) - soft.astype(int))[edge].mean() > 3


def test_fxaa_softens_edges_and_leaves_flat_areas_alone(gl, faces: Faces) -> None:
    with OffscreenRenderer(faces.model, (160, 120), ctx=gl) as off:
        hard = off.render_frame(faces.rest).astype(int)
        off.renderer.antialias = "fxaa"
        soft = off.render_frame(faces.rest).astype(int)
    skin = skin_mask(hard)
    edge = skin ^ np.roll(skin, 1, axis=1)
    near = edge.copy()
    for dy in (-2, -1, 0, 1, 2):
        for dx in (-2, -1, 0, 1, 2):
            near |= np.roll(np.roll(edge, dy, axis=0), dx, axis=1)
    diff = np.abs(hard - soft).sum(-1)
    assert diff[edge].mean() > 10
    assert (diff[~near & ~skin] == 0).mean() > 0.99  # plain background untouched
