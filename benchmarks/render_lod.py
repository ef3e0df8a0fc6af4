"""The scanned head's coarse plain skin (render.scan_lod) against the full skin, by picture: the seven
presets and the face at rest, simulated as docs/make_scan_gallery.py does, drawn live-size
(1280x720, one sample per pixel, shaded) with the level of detail forced each way; per preset the
largest and mean difference (levels of 255, the largest channel), the share of pixels that differ
by more than 2 and 8 levels, and the pixels whose head / background cover changed. With --out DIR,
each pair (full | coarse | difference x8) is written there as a PNG to be looked at. With --lashes,
the lashes alone: the coarse skin both times, the full lashes against the coarse ones
(render.scan_look.coarse_lashes), and the pictures cropped to the eyes, enlarged 3x.

Run: .venv/bin/python benchmarks/render_lod.py [--size 1280x720] [--out /tmp/lod] [--lashes]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--out", default="", help="a folder for the pictures (default: none written)")
    ap.add_argument("--only", default="", help="comma-separated presets (default: neutral and all seven)")
    ap.add_argument("--lashes", action="store_true", help="the full lashes against the coarse ones, the skin coarse")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "docs"))
    import numpy as np
    from make_scan_gallery import perform  # type: ignore[import-not-found]

    from puppet.face_cache import scan_model
    from render.offscreen import OffscreenRenderer
    from sim.facs import EXPRESSIONS

    model = scan_model(None)
    names = [n for n in args.only.split(",") if n] or ["neutral", *EXPRESSIONS]
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    with OffscreenRenderer(model, size) as off:  # type: ignore[arg-type]
        scan = off.renderer.scan
        print(f"{size[0]}x{size[1]}: the coarse skin's largest deviation {scan.lod_error * 10:.2f} mm; "
              f"drawn at this size by default: {scan.choose_level(off.renderer._matrices(size[0] / size[1])[1], size)}")
        print(f"{'preset':<10}{'max':>6}{'mean':>8}{'>2':>9}{'>8':>9}{'cover px':>10}{'plain tris':>16}")
        for name in names:
            state = perform(model, None if name == "neutral" else name)
            shots, drawn = [], []
            for lod in (False, True):
                scan.lod = lod or args.lashes
                scan.choose_level = _forced(scan, lod or args.lashes)  # type: ignore[method-assign]
                coarse_lashes = scan.coarse_lash_vao
                if args.lashes and not lod:
                    scan.coarse_lash_vao = scan.lash_vao
                shots.append(off.render_frame(state, record=False))
                scan.coarse_lash_vao = coarse_lashes
                drawn.append(int(scan.counts[0]))
                del scan.choose_level
            full, coarse = (s.astype(int) for s in shots)
            diff = np.abs(full - coarse).max(axis=2)
            bg = full[0, 0]
            cover = (np.abs(full - bg).sum(axis=2) > 0) != (np.abs(coarse - bg).sum(axis=2) > 0)
            print(f"{name:<10}{diff.max():>6}{diff.mean():>8.3f}{(diff > 2).mean() * 100:>8.2f}%"
                  f"{(diff > 8).mean() * 100:>8.3f}%{int(cover.sum()):>10}{drawn[0]:>8} ->{drawn[1]:>6}")
            if out:
                from PIL import Image

                d = np.clip(diff * 8, 0, 255).astype(np.uint8)
                pics = [shots[0], shots[1], np.stack([d] * 3, axis=2)]
                if args.lashes:  # the eyes: the rows and columns where the lashes differ, and a margin
                    whole = (np.array([0, size[1] - 1]), np.array([0, size[0] - 1]))
                    ys, xs = np.nonzero(diff) if diff.any() else whole
                    y0, y1 = max(ys.min() - 12, 0), min(ys.max() + 12, size[1])
                    x0, x1 = max(xs.min() - 12, 0), min(xs.max() + 12, size[0])
                    pics = [p[y0:y1, x0:x1].repeat(3, axis=0).repeat(3, axis=1) for p in pics]
                pic = np.concatenate(pics, axis=0 if args.lashes else 1)
                Image.fromarray(pic).save(out / f"{'lashes' if args.lashes else 'lod'}_{name}.png")
    return 0


def _forced(scan: object, coarse: bool):  # type: ignore[no-untyped-def]
    def choose(mvp: object, size: object) -> bool:
        scan.coarse = coarse  # type: ignore[attr-defined]
        return coarse

    return choose


if __name__ == "__main__":
    raise SystemExit(main())
