"""Give any head mesh the default face's rig (seed 003 section 3, extended from the wrinkle mask
to the whole rig): fit a cylinder to each face (eqs 1-7), unroll both, pin the reference's
characteristic points on the new face's and relax the reference mask as springs (eq 8), cast it
back onto the new surface and carry every rig element across. See docs/import-face.md."""

from sim.face.transfer.cylinder import Cylinder, fit_cylinder
from sim.face.transfer.landmarks import LANDMARK_NAMES, LandmarkFile, TransferError, parse_landmarks, read_landmarks
from sim.face.transfer.meshfile import HeadMesh, from_arrays, read_mesh
from sim.face.transfer.pipeline import Transfer, TransferOptions, transfer_rig

__all__ = [
    "Cylinder", "fit_cylinder", "LANDMARK_NAMES", "LandmarkFile", "TransferError", "parse_landmarks",
    "read_landmarks", "HeadMesh", "from_arrays", "read_mesh", "Transfer", "TransferOptions",
    "transfer_rig",
]
