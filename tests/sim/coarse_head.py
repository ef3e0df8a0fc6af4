"""A coarse transferred head: the default rig carried onto a 728-vertex synthetic full head (eye and
mouth holes, the back of the head included), the kind of low-polygon mesh a user imports."""

from __future__ import annotations

from functools import lru_cache

from sim.build import FaceModel, SkinParams, compile_model
from sim.model import FaceRig


@lru_cache(maxsize=1)
def coarse_head_rig() -> FaceRig:
    from sim.rig import default_rig
    from sim.transfer import from_arrays, parse_landmarks, transfer_rig
    from sim.transfer.synthetic import synthetic_landmarks, synthetic_mesh

    v, t, param = synthetic_mesh(28, 26, full_head=True)
    lms = parse_landmarks(synthetic_landmarks(t, param), "coarse.json")
    return transfer_rig(default_rig(0), from_arrays(v, t, "coarse.obj"), lms, name="coarse").rig


def coarse_head_model(params: SkinParams | None = None) -> FaceModel:
    return compile_model(coarse_head_rig(), params)
