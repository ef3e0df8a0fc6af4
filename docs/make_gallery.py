"""Writes the renderer's gallery to docs/images/: the seven basic expressions, each also side by
side with the neutral face (pair_<name>.png), a three-quarter and a profile view of the head, the
five views (seed 000 Fig. 2 and Fig. 8: shaded, wireframe, muscles in red, node trails,
displacement heat), and the HUD. Each expression is dialled in over 40 frames like a performer would, so the trails
show the motion. Run: .venv/bin/python docs/make_gallery.py [--size 640x480]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"
RAMP_FRAMES = 40
HOLD_FRAMES = 20


def perform(model: Any, expression: str, weight: float = 1.0) -> tuple[Any, list[Any]]:
    """Dial `expression` up from rest over RAMP_FRAMES, hold, settle; returns the final state and
    the surfaces of the ramp (oldest first) for the trails view."""
    from sim.facs import apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    sim = Simulator(model)
    state = model.rest_state()
    history = []
    control = FaceControl(model)
    for k in range(RAMP_FRAMES + HOLD_FRAMES):
        control = FaceControl(model)
        apply_expression(control, expression, weight * min(1.0, (k + 1) / RAMP_FRAMES))
        sim.step(state, control)
        if k < RAMP_FRAMES:
            history.append(state.surface.copy())
    sim.settle(state, control)
    return state, history


def _save(img: Any, name: str) -> Path:
    from PIL import Image

    path = OUT / name
    Image.fromarray(img).save(path, "PNG", optimize=True)
    print(f"wrote {path.relative_to(ROOT)} ({path.stat().st_size // 1024} KB)")
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="640x480", help="image size WxH (default 640x480)")
    ap.add_argument("--supersample", type=int, default=2, help="samples per pixel per axis (default 2)")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    sys.path.insert(0, str(ROOT))
    from render.hud import HudInfo, active_channels
    from render.offscreen import OffscreenRenderer
    from render.renderer import VIEWS
    from sim.face import default_model
    import numpy as np

    from sim.facs import EXPRESSIONS, apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    OUT.mkdir(parents=True, exist_ok=True)
    model = default_model(0)
    with OffscreenRenderer(model, size, supersample=args.supersample) as off:  # type: ignore[arg-type]
        tr = off.renderer.trails
        assert tr is not None
        poses = {name: perform(model, name) for name in EXPRESSIONS}
        off.view = "shaded"
        neutral = model.rest_state()
        Simulator(model).step(neutral, FaceControl(model))  # the rest pose (surface filled in)
        rest_img = off.render_frame(neutral, record=False)
        for name, (state, _) in poses.items():
            img = off.render_frame(state, record=False)
            _save(img, f"expression_{name}.png")
            _save(np.hstack([rest_img, img]), f"pair_{name}.png")
        cam = off.renderer.camera
        for yaw, name in ((0.6, "head_three_quarter.png"), (0.5 * np.pi, "head_profile.png")):
            cam.yaw = yaw
            _save(off.render_frame(poses["happiness"][0], record=False), name)
        cam.yaw = 0.0
        state, history = poses["happiness"]
        for view in VIEWS:
            off.view = view
            tr.set(history)
            _save(off.render_frame(state, record=False), f"view_{view}.png")
        off.view = "shaded"
        control = FaceControl(model)
        apply_expression(control, "surprise", 1.0)
        hud = HudInfo(channels=active_channels(model.channels, control.values), age=30,
                      devices=[("sgi:///dev/ttyS0", True), ("hid://0b33:0020", False)],
                      fps=59.9, latency_ms=11.8, lines=["? for keys"])
        _save(off.render_frame(poses["surprise"][0], hud=hud, record=False), "view_hud.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
