"""Rendering without a window: a standalone EGL context (Mesa's software rasterizer when there is no
GPU), a framebuffer of the requested size, the same FaceRenderer as the window. Used by
`puppet pose --out`, video export and the tests."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
from PIL import Image

from render.hud import HudInfo
from render.pipeline import FrameStream, find_rasterizer
from render.renderer import FaceRenderer

IMAGE_SUFFIXES = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}
#: the largest image side the commands accept: 8K, within every GL's renderbuffer limit we render
#: with (llvmpipe: 16384) and within memory when supersampled
MAX_IMAGE_SIDE = 8192
#: the largest side drawn, supersampling included (llvmpipe's renderbuffer and texture limit)
MAX_DRAWN_SIDE = 16384


def create_context() -> moderngl.Context:
    """A headless OpenGL 3.3+ context through EGL (one of the two places contexts are made); its
    rasterizer threads (llvmpipe's) listed for render.pipeline.steer_rasterizer."""
    ctx = moderngl.create_context(standalone=True, backend="egl", require=330)
    find_rasterizer()
    return ctx


class OffscreenRenderer:
    """Renders frames of one model at a fixed size into numpy arrays.

    `supersample` n renders n x n samples per pixel and averages them (offline quality);
    `antialias` "fxaa" adds the post pass instead (with supersample 1). Pass `ctx` to share a
    context (tests, many renderers); otherwise one is created and released by `release()`."""

    def __init__(self, model: Any, size: tuple[int, int] = (1280, 720), view: str = "shaded",
                 supersample: int = 1, ctx: moderngl.Context | None = None,
                 antialias: str = "none") -> None:
        self._own_ctx = ctx is None
        self.ctx = ctx if ctx is not None else create_context()
        self.size = (int(size[0]), int(size[1]))
        if min(self.size) < 1:
            raise ValueError(f"image size must be positive, got {size}")
        self._previous_fbo = self.ctx.fbo  # rebound on release so GL never points at a freed one
        self.renderer = FaceRenderer(self.ctx, view=view, antialias=antialias, supersample=supersample)
        self.renderer.populate(model)
        self._color = self.ctx.renderbuffer(self.size, 4)
        self._depth = self.ctx.depth_renderbuffer(self.size)
        self.fbo = self.ctx.framebuffer([self._color], self._depth)

    @property
    def view(self) -> str:
        return self.renderer.view

    @view.setter
    def view(self, name: str) -> None:
        self.renderer.view = name

    def render_frame(self, state: Any, hud: HudInfo | None = None, record: bool = True) -> np.ndarray:
        """(H, W, 3) uint8 image of `state`, top row first."""
        self.fbo.use()
        self.fbo.viewport = (0, 0, *self.size)
        self.renderer.draw(state, hud=hud, record=record)
        raw = self.fbo.read(components=3, alignment=1)
        img = np.frombuffer(raw, np.uint8).reshape(self.size[1], self.size[0], 3)
        return np.ascontiguousarray(img[::-1])

    def stream(self, pipelined: bool = True) -> FrameStream:
        """Frames drawn in a stream and read back (render.pipeline.FrameStream): pipelined, each
        frame's CPU half is made while the frame before rasterises (the same pixels)."""
        return FrameStream(self, pipelined)

    def release(self) -> None:
        if self.ctx.fbo is self.fbo:
            # moderngl rebinds ctx.fbo after creating framebuffers: never leave it on a freed one
            prev = self._previous_fbo
            (prev if prev is not None else self.ctx.detect_framebuffer(0)).use()
        self.renderer.release()
        self.fbo.release()
        self._color.release()
        self._depth.release()
        if self._own_ctx:
            self.ctx.release()

    def __enter__(self) -> "OffscreenRenderer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def save_image(img: np.ndarray, path: str | Path) -> Path:
    """Write an (H, W, 3) uint8 image as PNG or JPEG, chosen by the suffix."""
    path = Path(path)
    fmt = IMAGE_SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: unknown image type {path.suffix!r}; use .png, .jpg or .jpeg")
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(path, fmt, **({"quality": 92} if fmt == "JPEG" else {}))
    return path


def render_to_file(model: Any, state: Any, path: str | Path, size: tuple[int, int] = (1280, 720),
                   view: str = "shaded", history: Sequence[np.ndarray] | np.ndarray | None = None,
                   hud: HudInfo | None = None, supersample: int = 2,
                   ctx: moderngl.Context | None = None) -> Path:
    """Render one state to a PNG/JPEG file and return its path.

    history: surfaces (N, 3) oldest first for the trails view (the state is appended as newest);
    supersample: samples per pixel along each axis (2 = 4 samples, export quality)."""
    if Path(path).suffix.lower() not in IMAGE_SUFFIXES:
        raise ValueError(f"{path}: unknown image type; use .png, .jpg or .jpeg")
    with OffscreenRenderer(model, size, view=view, supersample=supersample, ctx=ctx) as off:
        if history is not None and len(history):
            assert off.renderer.trails is not None
            off.renderer.trails.set(history)
        img = off.render_frame(state, hud=hud)
    return save_image(img, path)
