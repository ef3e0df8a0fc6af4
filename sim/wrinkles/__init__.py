"""Expressive wrinkles (seed 003, Viaud & Yahia 1992): the reference wrinkle mask laid on the
face and the age-driven bulge of each wrinkle (section 5, eqs 10-14), applied to the drawn
surface every frame."""
