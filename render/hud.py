"""The heads-up display drawn over any view: active channels as bars, the face's age, device
status, fps and input-to-frame latency, and free lines (key help, messages). Text comes from a
glyph atlas rasterised once per size with Pillow. The HUD is drawn into a cached layer (a texture)
only when what it shows changes, and the fps / latency readings change it at most every
NUMBER_PERIOD s (as fast as anyone reads them); a frame composites the layer with one textured
quad per panel."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import moderngl
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from render import shaders

FONT_PATHS = (
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
)
CHARSET = ("".join(chr(c) for c in (*range(32, 127), *range(161, 256)))
           + "°±µ•·–—←→↑↓…≤≥×")

Color = tuple[float, float, float, float]
WHITE: Color = (0.95, 0.95, 0.95, 1.0)
DIM: Color = (0.75, 0.77, 0.80, 1.0)
PANEL: Color = (0.05, 0.06, 0.07, 0.55)
BAR_BG: Color = (1.0, 1.0, 1.0, 0.15)
BAR: Color = (0.98, 0.72, 0.30, 0.95)
OK: Color = (0.35, 0.85, 0.40, 1.0)
NUMBER_PERIOD = 0.25  # s: the shown fps / latency readings update at most this often
LOST: Color = (0.95, 0.30, 0.25, 1.0)


@dataclass
class HudInfo:
    """What the HUD shows; the live loop fills it each frame.

    channels: (name, value, lo, hi) of the channels to show (usually the active ones, see
    `active_channels`); age: years (None: the state's age); devices: (name, connected) or
    (name, connected, drops) where drops counts input the device lost to bursts (shown when > 0); fps, latency_ms: None hides them; lines: free text (key map, messages), drawn bottom-left."""

    channels: list[tuple[str, float, float, float]] = field(default_factory=list)
    age: float | None = None
    devices: list[tuple[str, bool] | tuple[str, bool, int | None]] = field(default_factory=list)
    fps: float | None = None
    latency_ms: float | None = None
    lines: list[str] = field(default_factory=list)


def active_channels(specs: Iterable[object], values: Sequence[float],
                    tol: float = 1e-6) -> list[tuple[str, float, float, float]]:
    """(name, value, lo, hi) of each channel whose value differs from its default.

    `specs` are `sim.channels.ChannelSpec`s (name, lo, hi, default), aligned with `values`."""
    out = []
    for spec, v in zip(specs, values):
        if abs(float(v) - float(spec.default)) > tol:  # type: ignore[attr-defined]
            lo, hi = float(spec.lo), float(spec.hi)  # type: ignore[attr-defined]
            out.append((spec.name, float(v), lo, hi))  # type: ignore[attr-defined]
    return out


def load_font(px: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """DejaVu Sans if installed (fonts-dejavu-core), else Pillow's built-in font."""
    for path in FONT_PATHS:
        if os.path.exists(path):
            return ImageFont.truetype(path, px)
    try:
        return ImageFont.load_default(size=px)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        return ImageFont.load_default()


class FontAtlas:
    """Every glyph of CHARSET in a grid of equal cells; `advance[ch]` is the pen advance in px."""

    def __init__(self, px: int) -> None:
        font = load_font(px)
        ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (px, px // 4)
        self.line = ascent + descent
        self.advance = {ch: float(font.getlength(ch)) for ch in CHARSET}
        self.cell_w = int(max(self.advance.values())) + 4
        self.cell_h = self.line + 2
        cols = 16
        rows = -(-len(CHARSET) // cols)
        img = Image.new("L", (cols * self.cell_w, rows * self.cell_h), 0)
        draw = ImageDraw.Draw(img)
        # per glyph: its ink box inside the cell (x, y, w, h in px) and that box in uv, so a quad
        # covers ink only (fill is what costs on a software rasterizer)
        self.box: dict[str, tuple[int, int, int, int]] = {}
        self.uv: dict[str, tuple[float, float, float, float]] = {}
        w, h = img.size
        for k, ch in enumerate(CHARSET):
            x, y = (k % cols) * self.cell_w, (k // cols) * self.cell_h
            draw.text((x + 1, y + 1), ch, fill=255, font=font)
            full = (0, 0, self.cell_w - 2, self.cell_h - 2)
            x0, y0, x1, y1 = font.getbbox(ch) if hasattr(font, "getbbox") else full
            x0, y0 = max(int(x0), -1), max(int(y0), -1)
            x1, y1 = min(int(x1) + 1, self.cell_w - 1), min(int(y1) + 1, self.cell_h - 1)
            self.box[ch] = (x0 + 1, y0 + 1, max(x1 - x0, 0), max(y1 - y0, 0))
            bx, by, bw, bh = self.box[ch]
            self.uv[ch] = ((x + bx) / w, (y + by) / h, (x + bx + bw) / w, (y + by + bh) / h)
        self.image = img

    def width(self, text: str) -> float:
        return sum(self.advance.get(ch, self.advance["?"]) for ch in text)


class HudRenderer:
    """Draws a `HudInfo` into the bound framebuffer, in pixels from the top-left corner."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=shaders.HUD_VS, fragment_shader=shaders.HUD_FS)
        self.vbo = ctx.buffer(reserve=8 * 4 * 6 * 512, dynamic=True)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f 2f 4f", "in_pos", "in_uv", "in_color")])
        self._atlas: tuple[int, FontAtlas, moderngl.Texture] | None = None
        self._quads: list[np.ndarray] = []  # (k, 12): x0 y0 x1 y1 u0 v0 u1 v1 r g b a
        self._text_cache: dict[tuple[object, ...], tuple[np.ndarray, float]] = {}
        self._key: tuple[object, ...] | None = None  # what the layer shows
        self._count = 0
        self.clock = time.monotonic  # for the readings' update period (tests replace it)
        self._readings: tuple[float | None, float | None] = (None, None)
        self._readings_t = -math.inf
        # the cached layer: premultiplied RGBA the size of the viewport, and the panel quads
        self.layer_prog = ctx.program(vertex_shader=shaders.HUD_LAYER_VS,
                                      fragment_shader=shaders.HUD_LAYER_FS)
        self.layer_vbo = ctx.buffer(reserve=2 * 4 * 6 * 16, dynamic=True)
        self.layer_vao = ctx.vertex_array(self.layer_prog, [(self.layer_vbo, "2f", "in_pos")])
        self._layer: tuple[tuple[int, int], moderngl.Texture, moderngl.Framebuffer, moderngl.Texture] | None = None
        self._layer_count = 0
        self._panels = np.zeros((0, 4))  # the pixels the layer is composited over: x0 y0 x1 y1 from the top-left

    def atlas(self, px: int) -> tuple[FontAtlas, moderngl.Texture]:
        if self._atlas is None or self._atlas[0] != px:
            if self._atlas is not None:
                self._atlas[2].release()
            fa = FontAtlas(px)
            self._text_cache.clear()
            tex = self.ctx.texture(fa.image.size, 1, fa.image.tobytes())
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
            self._atlas = (px, fa, tex)
        return self._atlas[1], self._atlas[2]

    # -- building quads -------------------------------------------------------------------------
    def rect(self, x: float, y: float, w: float, h: float, color: Color) -> None:
        self._quads.append(np.array([[x, y, x + w, y + h, -1.0, -1.0, -1.0, -1.0, *color]], np.float32))

    def text(self, fa: FontAtlas, x: float, y: float, s: str, color: Color) -> float:
        """Draw `s` with its top-left at (x, y); returns the pen position after it. The glyph
        quads of a string are laid out once (at the origin) and reused while it is shown."""
        x = float(round(x))
        y = float(round(y))
        key = (id(fa), s, color)
        hit = self._text_cache.get(key)
        if hit is None:
            rows, pen = [], 0.0
            for ch in s:
                k = ch if ch in fa.uv else "?"
                bx, by, bw, bh = fa.box[k]
                if bw and bh:
                    gx = float(round(pen)) + bx  # whole pixels keep NEAREST-sampled glyphs crisp
                    rows.append((gx, by, gx + bw, by + bh, *fa.uv[k], *color))
                pen += fa.advance.get(ch, fa.advance["?"])
            if len(self._text_cache) > 256:
                self._text_cache.clear()
            hit = self._text_cache[key] = (np.array(rows, np.float32).reshape(-1, 12), pen)
        quads, pen = hit
        if len(quads):
            q = quads.copy()
            q[:, [0, 2]] += x
            q[:, [1, 3]] += y
            self._quads.append(q)
        return x + pen

    # -- layout ---------------------------------------------------------------------------------
    def draw(self, info: HudInfo, size: tuple[int, int], view: str = "",
             age: float | None = None) -> None:
        w, h = size
        px = int(np.clip(round(h / 46), 11, 28))
        fa, tex = self.atlas(px)
        fps, latency = self._held_readings(info)
        if (fps, latency) != (info.fps, info.latency_ms):
            info = HudInfo(**{**info.__dict__, "fps": fps, "latency_ms": latency})
        shown = [None if x is None else round(float(x), 1) for x in (age, info.age, info.fps, info.latency_ms)]
        key = (px, w, h, view, *shown, tuple(info.channels),
               tuple(info.devices), tuple(info.lines))
        if key == self._key:  # unchanged since the layer was drawn: composite it again
            self._composite(size)
            return
        self._quads = []
        lh = round(fa.line * 1.25)
        pad = round(px * 0.6)
        self._channels(fa, info.channels, pad, lh)
        status = []
        if view:
            status.append((f"view: {view}", DIM))
        shown_age = info.age if info.age is not None else age
        if shown_age is not None:
            status.append((f"age {shown_age:.0f}", WHITE))
        if info.fps is not None:
            status.append((f"{info.fps:5.1f} fps", WHITE))
        if info.latency_ms is not None:
            status.append((f"latency {info.latency_ms:.1f} ms", WHITE))
        for name, connected, *drops in info.devices:
            word, color = ("connected", OK) if connected else ("lost", LOST)
            lost_input = f", {drops[0]} dropped" if drops and drops[0] else ""
            status.append((f"• {name} {word}{lost_input}", color))
        if status:
            pw = max(fa.width(s) for s, _ in status) + 2 * pad
            x0 = w - pw - pad
            self.rect(x0, pad, pw, len(status) * lh + pad, PANEL)
            for i, (s, c) in enumerate(status):
                self.text(fa, x0 + pad, pad + pad / 2 + i * lh, s, c)
        if info.lines:
            pw = max(fa.width(s) for s in info.lines) + 2 * pad
            ph = len(info.lines) * lh + pad
            y0 = h - ph - pad
            self.rect(pad, y0, pw, ph, PANEL)
            for i, s in enumerate(info.lines):
                self.text(fa, 2 * pad, y0 + pad / 2 + i * lh, s, WHITE)
        self._flush(tex, size)
        self._key = key
        self._composite(size)

    def _held_readings(self, info: HudInfo) -> tuple[float | None, float | None]:
        """The fps and latency to show: the given ones, but changed at most every NUMBER_PERIOD s
        (a reading that appears or disappears shows at once)."""
        now = self.clock()
        held = self._readings
        present = (info.fps is not None, info.latency_ms is not None)
        if present != (held[0] is not None, held[1] is not None) or now - self._readings_t >= NUMBER_PERIOD:
            self._readings, self._readings_t = (info.fps, info.latency_ms), now
        return self._readings

    def _channels(self, fa: FontAtlas, chans: Sequence[tuple[str, float, float, float]],
                  pad: int, lh: int) -> None:
        if not chans:
            return
        name_w = max(fa.width(c[0]) for c in chans)
        bar_w = fa.line * 6
        val_w = fa.width("-00.00")
        pw = name_w + bar_w + val_w + 4 * pad
        self.rect(pad, pad, pw, len(chans) * lh + pad, PANEL)
        for i, (name, v, lo, hi) in enumerate(chans):
            y = pad + pad / 2 + i * lh
            self.text(fa, 2 * pad, y, name, WHITE)
            bx, by, bh = 2 * pad + name_w + pad, y + fa.line * 0.25, fa.line * 0.55
            self.rect(bx, by, bar_w, bh, BAR_BG)
            span = (hi - lo) or 1.0
            zero = (min(max(0.0, lo), hi) - lo) / span      # bipolar channels grow from 0
            t = (min(max(v, lo), hi) - lo) / span
            a, b = sorted((zero, t))
            self.rect(bx + a * bar_w, by, max((b - a) * bar_w, 1.0), bh, BAR)
            text = f"{v:.2f}" if abs(v) < 10 else f"{v:.0f}"
            self.text(fa, bx + bar_w + pad, y, text, DIM)

    def _flush(self, tex: moderngl.Texture, size: tuple[int, int]) -> None:
        """Draw the quads into the layer (once per change of content) and set the panel quads
        that composite it."""
        self._count = self._layer_count = 0
        self._panels = np.zeros((0, 4))
        if not self._quads:
            return
        q = np.concatenate(self._quads)
        # two triangles per quad: corners (x0,y0) (x1,y0) (x1,y1) (x0,y0) (x1,y1) (x0,y1)
        xs, ys = np.array([0, 2, 2, 0, 2, 0]), np.array([1, 1, 3, 1, 3, 3])
        data = np.empty((len(q), 6, 8), np.float32)
        data[:, :, 0], data[:, :, 1] = q[:, xs], q[:, ys]
        data[:, :, 2], data[:, :, 3] = q[:, xs + 4], q[:, ys + 4]
        data[:, :, 4:] = q[:, None, 8:]
        data = data.reshape(-1, 8)
        raw = data.tobytes()
        if len(raw) > self.vbo.size:
            self.vbo.orphan(len(raw) * 2)
        self.vbo.write(raw)
        self._count = len(data)
        layer_tex, layer_fbo = self._layer_target(size)
        target = self.ctx.fbo
        layer_fbo.use()
        layer_fbo.clear(0.0, 0.0, 0.0, 0.0)
        # colour blended as over the frame; alpha accumulated as coverage: the layer ends up
        # premultiplied, and compositing it with (ONE, ONE_MINUS_SRC_ALPHA) equals drawing the
        # quads one after another over the frame
        self._render(tex, size, (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,
                                 moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA))
        if target is not None:
            target.use()
        rects = _regions(q)
        w, h = size
        x0 = np.clip(np.floor(rects[:, 0]), 0, w)
        y0 = np.clip(np.floor(rects[:, 1]), 0, h)
        x1 = np.clip(np.ceil(rects[:, 2]), 0, w)
        y1 = np.clip(np.ceil(rects[:, 3]), 0, h)
        self._panels = np.stack([x0, y0, x1, y1], axis=1)
        corners = np.stack([x0, y0, x1, y0, x1, y1, x0, y0, x1, y1, x0, y1], 1).astype(np.float32)
        raw = corners.tobytes()
        if len(raw) > self.layer_vbo.size:
            self.layer_vbo.orphan(len(raw) * 2)
        self.layer_vbo.write(raw)
        self._layer_count = 6 * len(rects)
        # the frames sample a copy that was never a render target: binding the layer (a
        # framebuffer's texture) for sampling made llvmpipe rasterise the frame drawn so far on the
        # spot, the HUD then in a second pass over the tiles (0.6-2.7 ms more CPU a frame at 720p)
        shown = self._layer[3]  # type: ignore[index]
        for a, b, c, d in zip(x0, y0, x1, y1):
            box = (int(a), int(h - d), int(c - a), int(d - b))
            if box[2] > 0 and box[3] > 0:
                shown.write(layer_fbo.read(viewport=box, components=4, alignment=1), viewport=box, alignment=1)

    def covers(self, box: tuple[float, float, float, float], margin: float = 0.0) -> bool:
        """Whether the HUD as last drawn composites over any pixel of `box` (x0 y0 x1 y1 in pixels
        from the top-left) widened by `margin` pixels."""
        p = self._panels
        if not len(p):
            return False
        x0, y0, x1, y1 = box[0] - margin, box[1] - margin, box[2] + margin, box[3] + margin
        return bool(((p[:, 0] < x1) & (p[:, 2] > x0) & (p[:, 1] < y1) & (p[:, 3] > y0)).any())

    def _layer_target(self, size: tuple[int, int]) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        """The layer drawn into and its framebuffer (a third texture, sampled by the frames, holds
        a copy of its panels)."""
        if self._layer is None or self._layer[0] != size:
            self._release_layer()
            tex = self.ctx.texture(size, 4)
            shown = self.ctx.texture(size, 4)
            shown.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._layer = (size, tex, self.ctx.framebuffer([tex]), shown)
        return self._layer[1], self._layer[2]

    def _release_layer(self) -> None:
        if self._layer is not None:
            for obj in reversed(self._layer[1:]):
                obj.release()  # type: ignore[attr-defined]
            self._layer = None

    def _render(self, tex: moderngl.Texture, size: tuple[int, int],
                blend: tuple[int, ...] = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA)) -> None:
        if not self._count:
            return
        self.prog["viewport"].value = (float(size[0]), float(size[1]))
        tex.use(0)
        self.prog["atlas"].value = 0
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_func = blend
        self.vao.render(moderngl.TRIANGLES, vertices=self._count)
        self.ctx.disable(moderngl.BLEND)

    def _composite(self, size: tuple[int, int]) -> None:
        """The cached layer over the bound framebuffer's viewport, one quad per panel."""
        if not self._layer_count or self._layer is None:
            return
        target = self.ctx.fbo
        vx, vy = target.viewport[:2] if target is not None else (0, 0)
        self.layer_prog["viewport"].value = (float(size[0]), float(size[1]))
        self.layer_prog["origin"].value = (int(vx), int(vy))
        self._layer[3].use(0)
        self.layer_prog["layer"].value = 0
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
        self.layer_vao.render(moderngl.TRIANGLES, vertices=self._layer_count)
        self.ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.prog, self.layer_vao, self.layer_vbo, self.layer_prog):
            obj.release()
        self._release_layer()
        if self._atlas is not None:
            self._atlas[2].release()


def _regions(q: np.ndarray) -> np.ndarray:
    """(R, 4) x0 y0 x1 y1 boxes covering every quad of `q` (rows x0 y0 x1 y1 ...): the panels,
    plus any quad that lies outside all of them."""
    panel = np.all(np.isclose(q[:, 8:12], PANEL), axis=1)
    boxes = q[panel, :4]
    rest = q[~panel, :4]
    if len(boxes):
        inside = ((rest[:, None, 0] >= boxes[None, :, 0] - 0.5) & (rest[:, None, 1] >= boxes[None, :, 1] - 0.5)
                  & (rest[:, None, 2] <= boxes[None, :, 2] + 0.5)
                  & (rest[:, None, 3] <= boxes[None, :, 3] + 0.5)).any(axis=1)
        rest = rest[~inside]
    return np.concatenate([boxes, rest]).astype(np.float64)
