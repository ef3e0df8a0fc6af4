"""The face's physics: skin springs, muscles, contact, wrinkles, integrators; faces themselves
(the procedural face, the head, rig placement and transfer) are built in `sim.face`. Knows nothing
of devices or OpenGL.

Public API (see docs/sim-api.md): `sim.face.default_model`, `compile_model`, `FaceModel`, `SkinParams`,
`FaceState`, `FaceControl`, `Simulator`, `GuardEvent`, `ChannelSpec`, `ChannelError`,
`CHANNEL_SPECS`. Imports are lazy so `import sim` stays cheap (numba loads on first use).
"""

from __future__ import annotations

from typing import Any

_EXPORTS = {
    "compile_model": "sim.build",
    "FaceModel": "sim.build",
    "SkinParams": "sim.build",
    "FaceState": "sim.state",
    "FaceControl": "sim.state",
    "Simulator": "sim.integrator",
    "GuardEvent": "sim.integrator",
    "ChannelSpec": "sim.channels",
    "ChannelError": "sim.channels",
    "CHANNEL_SPECS": "sim.channels",
    "load_rig": "sim.rig",
    "save_rig": "sim.rig",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'sim' has no attribute {name!r}")
