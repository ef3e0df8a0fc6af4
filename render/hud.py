"""The heads-up display drawn over any view: active channels as bars, the face's age, device
status, fps and input-to-frame latency, and free lines (key help, messages). Text comes from a
glyph atlas rasterised once per size with Pillow, so a frame costs one small buffer upload."""

from __future__ import annotations

import os
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
LOST: Color = (0.95, 0.30, 0.25, 1.0)


@dataclass
class HudInfo:
    """What the HUD shows; the live loop fills it each frame.

    channels: (name, value, lo, hi) of the channels to show (usually the active ones, see
    `active_channels`); age: years (None: the state's age); devices: (name, connected);
    fps, latency_ms: None hides them; lines: free text (key map, messages), drawn bottom-left."""

    channels: list[tuple[str, float, float, float]] = field(default_factory=list)
    age: float | None = None
    devices: list[tuple[str, bool]] = field(default_factory=list)
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
        self._key: tuple[object, ...] | None = None  # what the uploaded vertices show
        self._count = 0

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
        shown = [None if x is None else round(float(x), 1) for x in (age, info.age, info.fps, info.latency_ms)]
        key = (px, w, h, view, *shown, tuple(info.channels),
               tuple(info.devices), tuple(info.lines))
        if key == self._key:  # unchanged since the last frame: draw the uploaded vertices again
            self._render(tex, size)
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
        for name, connected in info.devices:
            word, color = ("connected", OK) if connected else ("lost", LOST)
            status.append((f"• {name} {word}", color))
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
        self._count = 0
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
        self._render(tex, size)

    def _render(self, tex: moderngl.Texture, size: tuple[int, int]) -> None:
        if not self._count:
            return
        self.prog["viewport"].value = (float(size[0]), float(size[1]))
        tex.use(0)
        self.prog["atlas"].value = 0
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        self.vao.render(moderngl.TRIANGLES, vertices=self._count)
        self.ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.prog):
            obj.release()
        if self._atlas is not None:
            self._atlas[2].release()
