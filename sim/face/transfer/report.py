"""The short markdown report written next to an imported rig, so the user can judge the fit."""

from __future__ import annotations

import numpy as np

from sim.model import LinearMuscle, SheetMuscle, SphincterMuscle
from sim.face.transfer.cylinder import Cylinder
from sim.face.transfer.pipeline import Transfer


def _cyl(c: Cylinder) -> str:
    return (f"radius {c.radius:.2f} cm, axis ({c.axis[0]:+.3f}, {c.axis[1]:+.3f}, {c.axis[2]:+.3f}), "
            f"RMS distance of the fitted skin {c.residual_rms:.2f} cm "
            f"({100 * c.residual_rms / c.radius:.1f} % of the radius), {c.iterations} CG iterations")


def format_report(t: Transfer, mesh_path: str, landmarks_path: str, seconds: float,
                  image: str | None = None) -> str:
    """Markdown: scale and orientation found, cylinder fits, relaxation, landmark distances,
    what was transferred and anything suspicious."""
    rig, m = t.rig, t.rig.mesh
    kinds = {"linear": LinearMuscle, "sphincter": SphincterMuscle, "sheet": SheetMuscle}
    parts = [p for ps in rig.muscles.values() for p in ps]
    count = {k: sum(isinstance(p, c) for p in parts) for k, c in kinds.items()}
    angle = np.degrees(np.arccos(np.clip((np.trace(t.similarity.rotation) - 1) / 2, -1, 1)))
    shape = sorted(t.shape_residuals.items(), key=lambda kv: -kv[1])
    lines = [
        f"# Imported face: {rig.name}",
        "",
        f"- mesh: `{mesh_path}`; landmarks: `{landmarks_path}`; took {seconds:.2f} s",
        f"- vertices {len(m.vertices)}, triangles {len(m.triangles)}"
        + (f" ({t.dropped_vertices} vertices of separate parts dropped)" if t.dropped_vertices else ""),
        f"- scale to cm: x{t.similarity.scale:.5g} (1 file unit = {t.similarity.scale:.4g} cm); "
        f"rotated {angle:.1f} degrees into the project frame"
        + ("; triangle winding flipped so normals point out of the skin" if t.flipped_winding else ""),
        f"- reference cylinder: {_cyl(t.reference_cylinder)}",
        f"- new-face cylinder: {_cyl(t.new_cylinder)}",
        f"- spring relaxation (eq 8): {t.relaxation.steps} steps, "
        + ("converged" if t.relaxation.converged else f"NOT converged (residual {t.relaxation.residual:.2g})")
        + f"; folded triangles {t.folded_triangles}; rays missing the surface {t.ray_misses}",
        f"- held (bound to the skull): {int(m.held.sum())} vertices, of which {t.outside_vertices} lie "
        "outside the reference mask",
        f"- muscles transferred: {len(parts)} parts on {len(rig.muscles)} channels "
        f"({count['linear']} linear, {count['sphincter']} sphincter, {count['sheet']} sheet)",
        f"- eyes: centres ({', '.join(f'{x:+.2f}' for x in m.eye_centers[0])}) and "
        f"({', '.join(f'{x:+.2f}' for x in m.eye_centers[1])}) cm, radius {m.eye_radius:.2f} cm; "
        f"eye loops {len(m.eye_loops[0])} + {len(m.eye_loops[1])} vertices, mouth loop {len(m.mouth_loop)}",
        f"- wrinkle lines transferred: {len(rig.wrinkles)}",
        "",
    ]
    if t.notes:
        lines += ["## Check", ""] + [f"- {n}" for n in t.notes] + [""]
    lines += [
        "## Landmark distances (cm)",
        "",
        "How far each landmark of the new face is from the reference face's after the best",
        "rotation + scale (shape difference; large values are where the faces differ most), and how",
        "far the reference landmark landed from it after the transfer (should be ~0).",
        "",
        "| landmark | shape difference | after transfer |",
        "|---|---:|---:|",
    ]
    lines += [f"| {n} | {d:.2f} | {t.landmark_errors.get(n, float('nan')):.3f} |" for n, d in shape]
    if image:
        lines += ["", f"![transferred muscles]({image})"]
    return "\n".join(lines) + "\n"
