"""A coarse transferred head (`sim.face.transfer.synthetic.coarse_transferred_head`, 437 vertices),
built once per test session."""

from __future__ import annotations

from functools import lru_cache

from sim.build import FaceModel, SkinParams, compile_model
from sim.model import FaceRig


@lru_cache(maxsize=1)
def coarse_head_rig() -> FaceRig:
    from sim.face.transfer.synthetic import coarse_transferred_head

    return coarse_transferred_head()


def coarse_head_model(params: SkinParams | None = None) -> FaceModel:
    return compile_model(coarse_head_rig(), params)
