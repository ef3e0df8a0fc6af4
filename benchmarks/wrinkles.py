"""What the wrinkles cost per frame on the default face: simulation + rendering with and without them.

Runs the same animated performance (a frown and a smile swept by a slow dial, age 75, so every
wrinkle is solved and displaced every frame) twice, interleaved in blocks, and prints the frame
costs and their ratio. Costs are CPU time of this process (all threads, so llvmpipe's rendering
threads count), which a shared, loaded machine disturbs far less than wall time; wall time is
printed too. The budget is 1.20 (wrinkles add at most 20 %); the exit status is 1 above it.

    .venv/bin/python benchmarks/wrinkles.py [--resolution 0] [--frames 240] [--no-render]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from sim.build import compile_model
from sim.facs import apply_au
from sim.integrator import Simulator
from sim.face import default_rig
from sim.state import FaceControl
from sim.wrinkles import layer_for

BUDGET = 1.20


def _control(model, t: float) -> FaceControl:  # type: ignore[no-untyped-def]
    """The performance at time t (s): AU4 and AU12 swept in antiphase, age 75."""
    c = FaceControl(model)
    c.set("age", 75.0)
    apply_au(c, "AU4", 0.5 + 0.5 * np.sin(2.0 * np.pi * 0.5 * t))
    apply_au(c, "AU12", 0.5 - 0.5 * np.sin(2.0 * np.pi * 0.5 * t))
    return c


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=0)
    ap.add_argument("--frames", type=int, default=240)
    ap.add_argument("--block", type=int, default=20)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args(argv)

    model = compile_model(default_rig(args.resolution))
    layer_for(model)  # compiled at rig build time in the app; not a per-frame cost
    sims = {True: Simulator(model, wrinkles=True), False: Simulator(model, wrinkles=False)}
    states = {k: model.rest_state() for k in sims}
    off = None
    if not args.no_render:
        from render.offscreen import OffscreenRenderer

        w, h = (int(v) for v in args.size.split("x"))
        off = OffscreenRenderer(model, (w, h), supersample=1)
    controls = [_control(model, i / 60.0) for i in range(args.frames)]

    def frame(with_wrinkles: bool, i: int) -> None:
        sims[with_wrinkles].step(states[with_wrinkles], controls[i])
        if off is not None:
            off.fbo.use()
            off.renderer.draw(states[with_wrinkles])
            off.ctx.finish()

    for k in (True, False):  # warm-up: numba, shaders, table
        for i in range(10):
            frame(k, i)
    spent = {True: 0.0, False: 0.0}
    wall = {True: 0.0, False: 0.0}
    for start in range(0, args.frames, args.block):
        for k in (False, True) if (start // args.block) % 2 else (True, False):
            t0, w0 = time.process_time(), time.perf_counter()
            for i in range(start, min(start + args.block, args.frames)):
                frame(k, i)
            spent[k] += time.process_time() - t0
            wall[k] += time.perf_counter() - w0
    if off is not None:
        off.release()
    per = {k: 1000.0 * v / args.frames for k, v in spent.items()}
    per_wall = {k: 1000.0 * v / args.frames for k, v in wall.items()}
    moved = float(np.abs(states[True].surface - states[True].positions).max())
    ratio = per[True] / per[False]
    what = "simulation" if args.no_render else f"simulation + rendering {args.size}"
    print(f"default face, resolution {args.resolution}: {model.n_vertices} vertices, "
          f"{len(model.rig.wrinkles)} wrinkle lines, {what}")
    print(f"  without wrinkles: {per[False]:.2f} ms CPU/frame ({per_wall[False]:.2f} ms wall)")
    print(f"  with wrinkles:    {per[True]:.2f} ms CPU/frame ({per_wall[True]:.2f} ms wall); "
          f"largest bulge at the end {10 * moved:.2f} mm")
    print(f"  ratio {ratio:.3f} CPU, {per_wall[True] / per_wall[False]:.3f} wall (budget {BUDGET:.2f})")
    return 0 if ratio <= BUDGET else 1


if __name__ == "__main__":
    sys.exit(main())
