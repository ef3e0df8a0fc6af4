"""Expressive wrinkles (seed 003, Viaud & Yahia 1992): the reference wrinkle mask laid on the
face and the age-driven bulge of each wrinkle (section 5, eqs 10-14), applied to the drawn
surface every frame. See docs/wrinkles.md.

- `default_mask(mesh)` -> the lines of the reference mask on a mesh (`FaceRig.wrinkles`);
- `apply_wrinkles(model, state)` sets `state.surface` = positions + bulges at `state.age`;
- `skin_params_for_age(age)` -> how the skin springs change with age.

Imports are lazy: laying out or loading a mask does not load numba.
"""

from __future__ import annotations

from typing import Any

_EXPORTS = {
    "AGE_0": "sim.wrinkles.bulge",
    "AGE_MAX": "sim.wrinkles.bulge",
    "DIL_MAX": "sim.wrinkles.bulge",
    "dilatation": "sim.wrinkles.bulge",
    "SkinParams": "sim.wrinkles.aging",
    "skin_params_for_age": "sim.wrinkles.aging",
    "WrinkleLayer": "sim.wrinkles.layer",
    "apply_wrinkles": "sim.wrinkles.layer",
    "compile_wrinkles": "sim.wrinkles.layer",
    "layer_for": "sim.wrinkles.layer",
    "WrinkleLine": "sim.wrinkles.mask",
    "default_mask": "sim.wrinkles.mask",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'sim.wrinkles' has no attribute {name!r}")
