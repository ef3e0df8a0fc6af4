"""The skin's material on an imported head where its geometry differs from the reference's in kind.

The normal support (`SkinParams.support`) stands for the tissue under the skin resisting
indentation along the rest normal. A modelled or scanned lid folds into the socket at its margin:
there the surface is turned down (or up, below the eye), so its normal points at the eyeball's gap
rather than into the tissue, and the support held the margin when the lid raiser or the brows pulled
it up (the development heads' lids opened 0.12-0.19 cm under AU5 where the built-in face's open
0.31). Where a lid faces away from the front, nothing lies under it along its normal: the support is
faded out there. A lid facing the front within 70 degrees keeps it whole, which every lid vertex of
the coarse transferred head of the tests and of the built-in face at resolution 0 does (at
resolutions 1 and 2 a few do not: 4 of 890 and 62 of 4,344). The rule is the transfer's: the
built-in faces themselves are not imported and keep their material."""

from __future__ import annotations

import numpy as np

from sim.model import FaceMesh
from sim.face.transfer.geometry import vertex_normals

FloatArray = np.ndarray
LID_REGIONS = ("upper_lid_l", "upper_lid_r", "lower_lid_l", "lower_lid_r")
FULL_SUPPORT_FACING = 0.35  # cos of the angle from the front within which a lid keeps its whole support
FORWARD = np.array([0.0, 0.0, 1.0])


def lid_support(mesh: FaceMesh) -> FloatArray | None:
    """(N,) multipliers of the normal support (`FaceRig.skin["support"]`): 1 everywhere but on lid
    vertices turned away from the front, where it falls linearly with the facing to 0 at a normal
    square to the front or turned back. None when no vertex needs less (the material is uniform)."""
    lids = np.zeros(len(mesh.vertices), bool)
    for name in LID_REGIONS:
        if name in mesh.regions:
            lids |= np.asarray(mesh.regions[name], bool)
    lids &= ~np.asarray(mesh.held, bool)
    facing = vertex_normals(np.asarray(mesh.vertices, float), np.asarray(mesh.triangles)) @ FORWARD
    mult = np.where(lids, np.clip(facing / FULL_SUPPORT_FACING, 0.0, 1.0), 1.0)
    return mult if (mult < 1.0).any() else None
