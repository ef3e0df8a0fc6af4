"""Pictures of the recognition templates: each preset's displacement flow field on the face seen
from the front, as the seed's Fig. 8 shows motion tracking: trails of the moving vertices from blue
where they start to red where they settle, motionless vertices as blue dots; or arrows from rest to the settled
pose coloured by length (blue short, red long). Drawn with Pillow; no OpenGL needed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

STILL_CM = 0.02  # below this (or STILL_SHARE of the largest motion) a vertex counts as motionless
STILL_SHARE = 0.06


def _ramp(u: float) -> tuple[int, int, int]:
    u = min(1.0, max(0.0, u))
    return int(40 + 215 * u), int(60 + 40 * (1 - abs(2 * u - 1))), int(255 - 215 * u)


def onset(model: Any, rest_state: Any, values: np.ndarray, seconds: float = 0.6) -> np.ndarray:
    """Positions (F, N, 3) per frame at 60 Hz from the settled rest once `values` are applied."""
    import sim

    s = sim.Simulator(model, 1 / 60.0, wrinkles=False)
    c = sim.FaceControl(model)
    c.values[...] = values
    st = rest_state.copy()
    out = [st.positions.copy()]
    for _ in range(int(round(seconds * 60))):
        s.step(st, c)
        out.append(st.positions.copy())
    return np.array(out)


def draw_template(model: Any, frames: np.ndarray, title: str, style: str = "trails",
                  size: tuple[int, int] = (560, 640), gain: float = 1.0) -> Image.Image:
    """One picture: frames (F, N, 3), the first at rest; gain magnifies the motion."""
    w, h = size
    rest = frames[0]
    lo, hi = rest[:, :2].min(axis=0), rest[:, :2].max(axis=0)
    scale = 0.86 * min(w / (hi[0] - lo[0]), (h - 40) / (hi[1] - lo[1]))
    cx, cy = (lo + hi) / 2

    def xy(p: np.ndarray) -> np.ndarray:  # front view: +X (the face's left) to the right, +Y up
        return np.stack([w / 2 + (p[..., 0] - cx) * scale, 20 + (h - 40) / 2 - (p[..., 1] - cy) * scale], axis=-1)

    img = Image.new("RGB", size, (250, 250, 248))
    d = ImageDraw.Draw(img)
    r2 = xy(rest)
    for a, b, c in model.triangles:
        d.polygon([tuple(r2[a]), tuple(r2[b]), tuple(r2[c])], outline=(222, 222, 226))
    moved = frames[0] + gain * (frames - frames[0])
    path = xy(moved)
    disp = np.linalg.norm(frames[-1] - frames[0], axis=1)
    top = max(float(disp.max()), 1e-9)
    still = max(STILL_CM, STILL_SHARE * top)
    for i in np.argsort(disp):
        if disp[i] < still:
            x, y = r2[i]
            d.ellipse([x - 1.2, y - 1.2, x + 1.2, y + 1.2], fill=(60, 90, 230))
            continue
        if style == "arrows":
            col = _ramp(disp[i] / top)
            (x0, y0), (x1, y1) = path[0, i], path[-1, i]
            d.line([(x0, y0), (x1, y1)], fill=col, width=2)
            v = np.array([x1 - x0, y1 - y0])
            n = float(np.linalg.norm(v))
            if n > 3:
                u, perp = v / n, np.array([-v[1], v[0]]) / n
                tip = np.array([x1, y1])
                head = min(6.0, 0.5 * n)
                d.polygon([tuple(tip), tuple(tip - head * u + 0.5 * head * perp),
                           tuple(tip - head * u - 0.5 * head * perp)], fill=col)
        else:
            pts = path[:, i]
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            along = np.cumsum(seg) / max(float(seg.sum()), 1e-9)  # colour by the share of the path travelled
            for k in range(len(pts) - 1):
                if seg[k] > 0.05:
                    d.line([tuple(pts[k]), tuple(pts[k + 1])], fill=_ramp(float(along[k])), width=2)
    d.text((10, 8), title, fill=(20, 20, 20))
    d.text((10, h - 18), f"max {top * 10:.1f} mm" + (f", motion x{gain:g}" if gain != 1 else ""), fill=(60, 60, 60))
    return img


def contact_sheet(images: list[Image.Image], columns: int = 4) -> Image.Image:
    w, h = images[0].size
    rows = (len(images) + columns - 1) // columns
    sheet = Image.new("RGB", (w * columns, h * rows), (255, 255, 255))
    for k, im in enumerate(images):
        sheet.paste(im, ((k % columns) * w, (k // columns) * h))
    return sheet


def save_png(img: Image.Image, path: Path) -> None:
    from puppet.capture.take import atomic_path

    with atomic_path(path, "picture") as tmp:
        img.save(tmp, format="PNG")
