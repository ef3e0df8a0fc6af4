"""Exports of the scanned head carry the lids as they are drawn: where anger's narrowed margins
sank 1.6 mm into the cornea in the simulated surface, the OBJ, the PC2 and `puppet pose --out`
(.obj, .npz) hold them laid back onto the eyeball (sim.face.scan.lid_contact), 26,719 vertices
in the scan's order, and the simulation's own state is not touched."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.face.scan.data import N_VERTICES, PARTS, SCLERA


@pytest.fixture(scope="module")
def angry():  # type: ignore[no-untyped-def]
    from puppet.face_cache import scan_model
    from sim.face.scan.dressing import dressing_for
    from sim.facs import apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    sim, state = Simulator(model, wrinkles=False), model.rest_state()
    c = FaceControl(model)
    apply_expression(c, "anger", 1.0, preset_face(model.rig))
    sim.settle(state, c, max_seconds=2.0)
    return model, dressing_for(model), state


def _margin_depth(posed: np.ndarray, dressing, rest: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    """mm: the deepest any lid margin vertex lies inside its eyeball's front beyond its depth at
    rest (0 or more where none sank): its distance from the eye's centre against the farthest
    eyeball vertex within 4 degrees of its direction, posed and at rest."""

    def depth(p: np.ndarray, k: int, side: str) -> np.ndarray:
        lo, _ = PARTS[f"eyeball_{side}"]
        shell = p[lo:lo + SCLERA].astype(np.float64) - dressing.eye_centres[k]
        out = []
        for v in margin:
            q = p[v].astype(np.float64) - dressing.eye_centres[k]
            u = q / np.linalg.norm(q)
            r = np.linalg.norm(shell, axis=1)
            near = shell @ u / r > np.cos(np.radians(4.0))
            out.append(np.linalg.norm(q) - r[near].max() if near.any() else np.inf)
        return np.array(out)

    worst = np.inf
    for k, side in enumerate("lr"):
        upper, lower = dressing.eye_margins[k]
        margin = np.concatenate([upper[1:-1], lower[1:-1]])
        worst = min(worst, float((depth(posed, k, side) - np.minimum(depth(rest, k, side), 0.0)).min()))
    return 10.0 * worst


def _obj_vertices(path: Path) -> np.ndarray:
    return np.array([[float(x) for x in ln.split()[1:4]] for ln in path.read_text().splitlines()
                     if ln.startswith("v ")])


def test_pose_out_obj_and_npz_hold_the_lids_on_the_eyeballs(tmp_path: Path, angry) -> None:  # type: ignore[no-untyped-def]
    from puppet.cmd_pose import write_pose
    from sim.face.scan.blendshapes import StateControl

    model, dressing, state = angry
    surface = np.array(state.surface, copy=True)
    simulated = dressing.pose_turned(np.asarray(state.surface), StateControl(state), state)
    assert _margin_depth(simulated, dressing, dressing.rest) < -1.0  # as simulated: sunk over a millimetre
    write_pose(model, state, tmp_path / "anger.obj")
    write_pose(model, state, tmp_path / "anger.npz")
    obj = _obj_vertices(tmp_path / "anger.obj")
    with np.load(tmp_path / "anger.npz") as z:
        npz = z["scan_positions"]
    assert obj.shape == npz.shape == (N_VERTICES, 3)
    assert np.abs(obj - npz).max() < 1e-5  # the two files agree
    assert _margin_depth(npz, dressing, dressing.rest) > -0.2  # exported: on the eyeball's front
    # only the lids and what hangs from them moved, around the eyes; the simulation's state untouched
    changed = np.flatnonzero(np.linalg.norm(npz - simulated, axis=1) > 1e-6)
    assert len(changed) and np.linalg.norm(npz[changed, None] - dressing.eye_centres[None], axis=2).min(axis=1).max() < 3.0
    assert np.array_equal(np.asarray(state.surface), surface)


def test_pc2_samples_are_the_pose_as_exported(tmp_path: Path, angry) -> None:  # type: ignore[no-untyped-def]
    """The point cache writes what `puppet pose --out` writes for the same state (one code path)."""
    from puppet.export.pc2 import PC2Writer, read_pc2
    from puppet.export.scan import posed

    model, dressing, state = angry
    w = PC2Writer(tmp_path / "a.pc2", N_VERTICES)
    w.add(posed(dressing, state))
    w.close()
    _, samples = read_pc2(tmp_path / "a.pc2")
    assert _margin_depth(samples[0], dressing, dressing.rest) > -0.2
