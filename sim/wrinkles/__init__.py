"""Expressive wrinkles (seed 003, Viaud & Yahia 1992): the reference wrinkle mask laid on the
face and the age-driven bulge of each wrinkle (section 5, eqs 10-14), applied to the drawn
surface every frame. See docs/wrinkles.md.

- `default_mask(mesh)` -> the lines of the reference mask on a mesh (`FaceRig.wrinkles`);
- `apply_wrinkles(model, state)` sets `state.surface` = positions + bulges at `state.age`;
- `skin_params_for_age(age)` -> how the skin springs change with age.
"""

from sim.wrinkles.aging import SkinParams, skin_params_for_age
from sim.wrinkles.bulge import AGE_0, AGE_MAX, DIL_MAX, dilatation
from sim.wrinkles.layer import WrinkleLayer, apply_wrinkles, compile_wrinkles, layer_for
from sim.wrinkles.mask import WrinkleLine, default_mask

__all__ = [
    "AGE_0",
    "AGE_MAX",
    "DIL_MAX",
    "SkinParams",
    "WrinkleLayer",
    "WrinkleLine",
    "apply_wrinkles",
    "compile_wrinkles",
    "default_mask",
    "dilatation",
    "layer_for",
    "skin_params_for_age",
]
