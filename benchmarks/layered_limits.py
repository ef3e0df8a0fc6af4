"""How close to the scans smooth muscle forces could come on a layered face (run by hand).

`scan_limits.py`'s "gains free per shape" measure (in the linear statics, every muscle's insertion
gain free per skin vertex and per shape, non-negative, Laplacian-smoothed exactly as there, each
vertex pulled along the muscles' fixed lines of action; the map's settled pose minus its linear
prediction kept as an offset), on the shipped single sheet and on layered tissue
(`sim.layered`, `sim.face.scan.layers`): the skin over a deep layer over bone, the muscles pulling
the deep layer. Relative RMS error over the simulated skin, as `scan_match.py`.

Each layered variant's stiffness is scaled so that the placed muscles (the map's channels, gain 1)
move the skin as far as on the sheet (the factor is printed), so a laxer model does not win by
needing smaller, and so less penalised, gains.

    nice .venv/bin/python benchmarks/layered_limits.py [--shapes browDown_L,...] [--variants uniform,ligaments]
        [--maxiter 500] [--no-sheet]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from scan_limits import Free, ceiling_table, scale_like, settled_shapes  # noqa: E402

SHAPES = ("browDown_L,mouthClose,mouthDimple_L,mouthFunnel,mouthPress_L,mouthShrugLower,BrowInnerUp,"
          "mouthSmile_L")
# name: (deep layer's modulus per skin spring, skin-deep shear, deep-bone shear, muscles on which layer);
# a shear "lig:a:b" is a over fat and b on the retaining ligaments (`sim.face.scan.layers.ligaments`)
VARIANTS = {
    "uniform": (1.0, 1.0, 1.0, "deep"),
    "uniform-skin": (1.0, 1.0, 1.0, "skin"),
    "no-deep": (0.01, 1.0, 1.0, "deep"),  # the deep layer without stiffness of its own
    "smas": (3.0, 0.3, 1.0, "deep"),  # a stiffer deep sheet the skin slides over
    "float": (10.0, 0.05, 1.0, "deep"),  # the same, further
    "ligaments": (1.0, "lig:0.3:5", "lig:0.3:5", "deep"),
    "ligaments-strong": (1.0, "lig:0.05:20", "lig:0.05:20", "deep"),
    "ligaments-smas": (3.0, "lig:0.1:10", 1.0, "deep"),
}


class Sheet(Free):
    """The shipped single sheet with its springs' modulus (bending springs included) scaled by
    `modulus`: how far a smooth pull spreads (the spread's length goes with sqrt(modulus / tether))."""

    def __init__(self, model, modulus: float) -> None:  # type: ignore[no-untyped-def]
        from dataclasses import replace

        from sim.face.scan.calibrate import _stiffness

        super().__init__(model)
        self.lu, self.free = _stiffness(replace(model, spring_k_low=np.asarray(model.spring_k_low) * modulus))
        self.scale = 1.0

    def solve(self, f: np.ndarray) -> np.ndarray:
        return self.scale * super().solve(f)


class Layered(Free):
    """scan_limits' free fits with the forces on a layer of `sim.layered`'s tissue and the skin's
    displacement read off: u_skin = S^T K^-1 L f (K symmetric: the adjoint is L^T K^-1 S r)."""

    def __init__(self, model, deep_modulus: float, skin_shear, bone_shear, on: str) -> None:  # type: ignore[no-untyped-def]
        from scipy.sparse.linalg import splu

        from sim.face.scan.layers import ligaments, tissue_thickness
        from sim.layered import DEEP, SKIN, layered

        super().__init__(model)
        lig = ligaments(model)

        def mult(v):  # type: ignore[no-untyped-def]
            if isinstance(v, str):
                lax, tight = (float(x) for x in v.split(":")[1:])
                return lax + (tight - lax) * lig
            return float(v)

        self.layers = layered(np.asarray(model.rest), np.asarray(model.rest_normal), model.rig.mesh.triangles,
                              np.asarray(model.spring_indices), np.asarray(model.spring_k_low),
                              np.asarray(model.support_stiffness), np.asarray(model.rest_stiffness),
                              np.asarray(model.held, bool), 0.5 * tissue_thickness(model), deep_modulus,
                              mult(skin_shear), mult(bone_shear))
        k = self.layers.stiffness()
        self.free_l = self.layers.free_dofs()
        self.lu_l = splu(k[self.free_l][:, self.free_l].tocsc())
        self.on = DEEP if on == "deep" else SKIN
        self.scale = 1.0

    def _apply(self, f: np.ndarray, into: int, out_of: int) -> np.ndarray:
        n = self.n
        rhs = np.zeros(9 * n)
        rhs[3 * n * into:3 * n * (into + 1)] = f.ravel()
        x = np.zeros(9 * n)
        x[self.free_l] = self.lu_l.solve(np.ascontiguousarray(rhs[self.free_l]))
        return self.scale * x[3 * n * out_of:3 * n * (out_of + 1)].reshape(n, 3)

    def solve(self, f: np.ndarray) -> np.ndarray:
        return self._apply(f, self.on, 0)

    def adjoint(self, r: np.ndarray) -> np.ndarray:
        return self._apply(r, 0, self.on)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default=SHAPES, help="comma-separated scan or ARKit names (BrowInnerUp: both halves)")
    ap.add_argument("--variants", default="uniform,no-deep,smas,ligaments-strong,ligaments",
                    help=f"of {', '.join(VARIANTS)}, or sheet:M (the sheet's springs times M)")
    ap.add_argument("--maxiter", type=int, default=Free.MAXITER, help="L-BFGS-B iterations a fit")
    ap.add_argument("--no-sheet", action="store_true", help="leave out the shipped sheet's own fit")
    args = ap.parse_args()
    Free.MAXITER = args.maxiter
    t0 = time.monotonic()
    model, targets, values, real, sheet = settled_shapes(args.shapes)
    models = {} if args.no_sheet else {"sheet": sheet}
    for name in args.variants.split(","):
        m = Sheet(model, float(name.split(":")[1])) if name.startswith("sheet:") else Layered(model, *VARIANTS[name])
        scale_like(name, m, sheet, values)
        models[name] = m
    print(f"settled and built in {time.monotonic() - t0:.0f} s")
    print(f"{'shape':20s} {'map':>5s} " + " ".join(f"{k:>14s}" for k in models))
    ceiling_table(targets, real, values, models, lambda name, m, wanted: (m.best_gains(wanted), None), 14, t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
