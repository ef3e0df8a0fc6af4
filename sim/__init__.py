"""The face: rig building, skin springs, muscles, wrinkles, integrator. Knows nothing of devices
or OpenGL.

Public API (see docs/sim-api.md): `default_model`, `compile_model`, `FaceModel`, `SkinParams`,
`FaceState`, `FaceControl`, `Simulator`, `GuardEvent`, `ChannelSpec`, `ChannelError`,
`CHANNEL_SPECS`. Imports are lazy so `import sim` stays cheap (numba loads on first use).
"""

from __future__ import annotations

from typing import Any

_EXPORTS = {
    "default_model": "sim.build",
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
    "default_rig": "sim.rig",
    "load_rig": "sim.rig",
    "save_rig": "sim.rig",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'sim' has no attribute {name!r}")
