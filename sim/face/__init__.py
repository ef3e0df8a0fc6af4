"""Faces: the assets and builders a simulation runs on, apart from the physics.

The procedural face (`builder`, `chart`, `shape`, `constrain`, `regions`), the head around it
(`head`), muscle placement from landmarks (`placement`), the transfer of a rig onto another mesh
(`transfer`) and the amplitude targets measured on real faces (`targets`). Imports go one way: this
package builds on the physics (`sim.model`, `sim.build`, `sim.springs`, `sim.wrinkles`); nothing in
the physics imports it.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sim.build import FaceModel
    from sim.model import FaceMesh, FaceRig


def default_rig(resolution: int = 0) -> FaceRig:
    """The procedural default face with muscles placed from its landmarks."""
    from sim.face.builder import build_face_mesh
    from sim.face.placement import place_muscles
    from sim.model import FaceRig

    mesh = build_face_mesh(resolution)
    return FaceRig(mesh=mesh, muscles=place_muscles(mesh), wrinkles=default_wrinkles(mesh),
                   name=f"default-{resolution}")


def default_wrinkles(mesh: FaceMesh) -> tuple:
    """The reference wrinkle mask laid on this mesh."""
    from sim.wrinkles.mask import default_mask

    return tuple(default_mask(mesh))


@lru_cache(maxsize=4)
def default_model(resolution: int = 0) -> FaceModel:
    """The default face at a mesh resolution (0 ~ 700 vertices, 1 ~ 3k, 2 ~ 12k), cached."""
    from sim.build import compile_model

    return compile_model(default_rig(resolution))
