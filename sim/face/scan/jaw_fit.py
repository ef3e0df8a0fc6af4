"""The scanned head's jaw fitted to the scan's own jaw shapes (run once, its result shipped in
`ict_rig.npz`):

- the hinge (`opening_pivot`): the transfer put the reference face's hinge 2.2 cm in front of and
  below the turn the scan's `jawOpen` makes, so the simulated chin went down rather than back (the
  lower teeth's rigid motion 13 mm RMS from the scan's at jaw = 1). The scan opens its jaw 25.3
  degrees; our jaw turns 0.55 rad (31.5 degrees) at 1 and glides forward and down with it
  (`sim.integrator.jaw_motion`), so ARKit's jawOpen at 1 is the jaw at `OPENING_SPAN` and the pivot
  is the point about which that turn and glide carry the lower teeth where the scan has them;
- the skin's jaw weights (`settled_weights`): read off the scan's jawOpen as each vertex's share of
  the teeth's rigid motion, they are where the skin's tether anchors go, and the skin settles short
  of its anchors, held back by the skin still on the skull (the chin made 0.64 of the bone's motion
  on weights of 0.77 where the scan's chin makes 0.88). Each round settles jawOpen, jawForward,
  jawLeft and jawRight and adds to every weight what the settled skin still misses along the
  bone's motion over the four, least squares, smoothed over the mesh.

    python -m sim.face.scan.jaw_fit [--rig sim/face/scan/ict_rig.npz]

rewrites the rig file's hinge and jaw weights, everything else as it is (docs/scan-face.md, "The
jaw's hinge and the skin carried by the mandible").
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

#: ARKit's jawOpen at 1 is the jaw channel at this value: the scan's opening (25.3 degrees) over
#: our jaw's turn at 1 (0.55 rad); puppet/export/arkit.py's SHAPE_SPAN holds the same number
OPENING_SPAN = 0.8
#: the jaw shapes the weights are fitted on and the jaw channels each drives at 1
JAW_SHAPES = {"jawOpen": {"jaw": OPENING_SPAN}, "jawForward": {"jaw_forward": 1.0},
              "jawLeft": {"jaw_sideways": 1.0}, "jawRight": {"jaw_sideways": -1.0}}
ROUNDS = 2
SMOOTHING = 10  # Jacobi passes of neighbour averaging over each round's change (a ~1.5 cm kernel)
MOVING = 0.04  # cm2: a vertex whose rigid motion, squared and summed over the shapes, is below this keeps its weight


def teeth_motion(name: str = "jawOpen") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lower teeth's rest points (T, 3), rotation (3, 3), translation (3,)) of the scan's shape:
    the rigid motion fitted to its lower teeth (cm, the scan's frame)."""
    from sim.face.scan.data import PARTS, scan_data
    from sim.face.scan.dressing import TEETH_SPLIT
    from sim.face.scan.make_rig import _rigid_fit
    from sim.face.scan.rig import scan_points

    points = scan_points(None)[TEETH_SPLIT:PARTS["teeth"][1]]
    rot, t = _rigid_fit(points, points + scan_data().expression(name)[TEETH_SPLIT:PARTS["teeth"][1]])
    return points, rot, t


def opening_pivot(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(3,) cm: the hinge's point (on the model's own axis, at its pivot's depth along it) about
    which the jaw opened to `OPENING_SPAN` (the turn and the condyles' glide of
    `sim.integrator.jaw_motion`) carries the scan's lower teeth where its jawOpen has them, least
    squares over the teeth: (R - I) p = R q + t - (R_ours q + glide) for every tooth point q."""
    from sim.integrator import jaw_motion

    q, rot, t = teeth_motion()
    ours, glide = jaw_motion(model, OPENING_SPAN)
    pivot = np.asarray(model.jaw_pivot, np.float64)
    # x = (q - p) R_o^T + p + g  ->  (I - R_o) p = q R^T + t - q R_o^T - g, the axis' coordinate kept
    rhs = (q @ rot.T + t - q @ ours.T - glide).ravel()
    a = np.tile(np.eye(3) - ours, (len(q), 1))
    axis = int(np.argmax(np.abs(np.asarray(model.jaw_axis, np.float64))))
    keep = [k for k in range(3) if k != axis]
    rhs = rhs - a[:, axis] * pivot[axis]
    sol, *_ = np.linalg.lstsq(a[:, keep], rhs, rcond=None)
    out = pivot.copy()
    out[keep] = sol
    return out


def rigid_motion(model, values: dict[str, float]) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N, 3) cm: each vertex carried rigidly by the mandible under the jaw channels `values`."""
    from sim.integrator import jaw_motion

    rot, slide = jaw_motion(model, values.get("jaw", 0.0), values.get("jaw_forward", 0.0),
                            values.get("jaw_sideways", 0.0))
    rest = np.asarray(model.rest, np.float64)
    pivot = np.asarray(model.jaw_pivot, np.float64)
    return (rest - pivot) @ rot.T + pivot + slide - rest


def _smooth(triangles: np.ndarray, n: int, x: np.ndarray, passes: int) -> np.ndarray:
    import scipy.sparse as sp

    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    adj = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()
    adj.data[:] = 1.0
    degree = np.asarray(adj.sum(axis=1)).ravel()
    for _ in range(passes):
        x = 0.5 * x + 0.5 * (adj @ x) / degree
    return x


def settled_errors(model) -> dict[str, tuple[np.ndarray, np.ndarray]]:  # type: ignore[no-untyped-def]
    """{shape: (settled displacement (N, 3), the scan's (N, 3))} of the jaw shapes, cm."""
    from sim.face.scan.anatomy import skin_layout
    from sim.face.scan.data import scan_data
    from sim.fit.basis import Settler

    settler = Settler(model)
    skin = skin_layout().vertices
    out = {}
    for name, values in JAW_SHAPES.items():
        out[name] = (settler.pose(settler.values_for(values)) - settler.rest, scan_data().expression(name)[skin])
    return out


def settled_weights(rig, params, rounds: int = ROUNDS, report=None):  # type: ignore[no-untyped-def]
    """The rig with its jaw weights refitted so that the settled jaw shapes follow the scan's
    along the bone's motion (module docstring); `report(round, {shape: relative error})`."""
    from sim.build import compile_model
    from sim.face.scan.rig import _r

    tris = np.asarray(rig.mesh.triangles)
    w = np.asarray(rig.mesh.jaw_weight, np.float64)
    for k in range(rounds + 1):
        model = compile_model(rig, params)
        num = np.zeros(len(w))
        den = np.zeros(len(w))
        rel = {}
        for name, (pose, scan) in settled_errors(model).items():
            bone = rigid_motion(model, JAW_SHAPES[name])
            num += np.einsum("ij,ij->i", bone, scan - pose)
            den += np.einsum("ij,ij->i", bone, bone)
            rel[name] = float(np.sqrt(np.sum((pose - scan) ** 2) / np.sum(scan * scan)))
        if report is not None:
            report(k, rel)
        if k == rounds:
            break
        change = np.where(den > MOVING, num / np.maximum(den, 1e-12), 0.0)
        w = _r(np.clip(w + _smooth(tris, len(w), change, SMOOTHING), 0.0, 1.0))
        rig = replace(rig, mesh=replace(rig.mesh, jaw_weight=w))
    return rig


def fit_jaw(rig, params, rounds: int = ROUNDS, report=None):  # type: ignore[no-untyped-def]
    """The rig with the hinge at `opening_pivot` and the jaw weights `settled_weights`."""
    from sim.build import compile_model
    from sim.face.scan.rig import _r

    pivot = _r(opening_pivot(compile_model(rig, params)))
    return settled_weights(replace(rig, mesh=replace(rig.mesh, jaw_pivot=pivot)), params, rounds, report)


def main(argv: list[str] | None = None) -> int:
    from sim.face.scan.rig import RIG_FILE, scan_params
    from sim.rig import load_rig, save_rig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", type=Path, default=RIG_FILE, help="the rig file to rewrite")
    args = ap.parse_args(argv)
    rig = load_rig(args.rig)

    def report(k: int, rel: dict[str, float]) -> None:
        print(f"round {k}: " + ", ".join(f"{s} {r:.3f}" for s, r in rel.items()), flush=True)

    fitted = fit_jaw(rig, scan_params(), report=report)
    print(f"hinge {np.asarray(rig.mesh.jaw_pivot)} -> {np.asarray(fitted.mesh.jaw_pivot)}")
    save_rig(fitted, args.rig)
    print(f"wrote {args.rig}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
