"""The default face is a head: a held cranium, ears and neck around the simulated mask
(sim.face_head), in adult proportions, never in front of the face, and only for the default rig."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.face_head import head_shell, shell_for
from sim.rig import default_rig


def test_head_proportions_and_mesh() -> None:
    rig = default_rig(0)
    shell = shell_for(rig)
    assert shell is not None
    v, t = shell.vertices, shell.triangles
    assert t.min() >= 0 and t.max() < len(v) and np.isfinite(v).all()
    assert ((shell.hair >= 0) & (shell.hair <= 1)).all() and shell.hair.max() == 1.0
    chin_y = rig.mesh.landmark("chin")[1]
    assert 21.0 < v[:, 1].max() - chin_y < 25.0  # vertex to chin ~23 cm
    assert 13.0 < np.ptp(v[v[:, 1] > -6.0, 0]) < 17.5  # breadth with the ears
    back = v[v[:, 1] > -6.0, 2].min()
    assert 17.0 < rig.mesh.landmark("glabella")[2] - back < 21.0  # glabella to the back ~19 cm
    assert v[:, 1].min() < chin_y - 5.0  # a neck below the chin


def test_head_stays_behind_the_face() -> None:
    """Along the viewing direction no head vertex lies in front of the mask where the mask is
    (so the cranium never shows through the skin)."""
    mesh = default_rig(0).mesh
    shell = head_shell(mesh)
    from scipy.spatial import cKDTree

    tree = cKDTree(mesh.vertices[:, :2])
    d, i = tree.query(shell.vertices[:, :2])
    inside = (d < 0.3) & (np.abs(shell.vertices[:, 0]) < 5.5) & (shell.vertices[:, 1] > -11.0)
    assert inside.sum() > 50
    assert (shell.vertices[inside, 2] < mesh.vertices[i[inside], 2] + 0.05).mean() > 0.99


def test_only_the_default_face_gets_a_head() -> None:
    rig = default_rig(0)
    assert shell_for(dataclasses.replace(rig, name="imported")) is None
