"""How age changes the skin's elasticity (seed 003 section 2; seed 000 eqs 1-3 springs).

Seed 003 says ageing thins the elastic fibres of the hypodermis and unfolds the dermo-epidermal
junction, "considerably changing the skin's elasticity", but gives no law. Our documented choice,
on the same ramp as the dilatation of eq 10 (nothing before AGE_0, linear up to AGE_MAX):

- the low-strain stiffness k_l (elastic fibres) falls linearly to K_LOW_AT_MAX of its young value
  (the same fraction of a compression then goes into the bulge, `bulge.released_surplus`);
- the strain threshold eps^c (where collagen engages, seed 000 eq 3) rises by THRESHOLD_SHIFT_AT_MAX:
  the unfolded junction lets the skin stretch further before it stiffens;
- the high-strain stiffness k_h (collagen) is unchanged, so the integrator's stable step, bounded
  by k_h, never shrinks with age.
"""

from __future__ import annotations

from typing import NamedTuple

from sim.wrinkles.bulge import AGE_0, AGE_MAX, INPLANE_LOSS_AT_MAX

K_LOW_AT_MAX = 1.0 - INPLANE_LOSS_AT_MAX
THRESHOLD_SHIFT_AT_MAX = 0.1


class SkinParams(NamedTuple):
    """Age-adjusted spring parameters: multiply the model's spring_k_low / spring_k_high by the
    scales; strain_threshold is the relative strain eps^c to use instead of the model's. (A named
    tuple: made every tick the age moves, 1.5 us less than a frozen dataclass.)"""

    k_low_scale: float
    k_high_scale: float
    strain_threshold: float


def age_fraction(age: float) -> float:
    """0 up to AGE_0, 1 from AGE_MAX on, linear between (the ramp of eq 10). On floats, not
    numpy's clip (the same value, NaN kept; 14 us a call, made every tick the age moves)."""
    return min(max(float((age - AGE_0) / (AGE_MAX - AGE_0)), 0.0), 1.0)


def skin_params_for_age(age: float, base_threshold: float = 0.15) -> SkinParams:
    """The skin's spring parameters at `age` years, relative to the young skin the model was
    compiled with (`base_threshold` is its eps^c)."""
    f = age_fraction(age)
    return SkinParams(
        k_low_scale=1.0 - (1.0 - K_LOW_AT_MAX) * f,
        k_high_scale=1.0,
        strain_threshold=base_threshold + THRESHOLD_SHIFT_AT_MAX * f,
    )
