"""The reference wrinkle mask (seed 003 sections 2-3): the expressive wrinkles every face can form,
after Hjortsjo's atlas, each with the muscles whose contraction compresses the skin across it.

The paper aligns spline isolines with the wrinkles and transfers the mask between faces by
flattening and relaxing it around characteristic points. We keep the idea without the spline
surface: each line is a polyline in frontal (x, y) cm laid out from characteristic points every
`FaceMesh` has (eye centres and corners from the eye loops, mouth corners from the mouth loop),
with offsets given on a reference face (inter-pupillary distance REFERENCE_IPD) and scaled by the
face's own size. `sim.wrinkles.layer` projects the lines onto the skin along -Z, so they land on
the same anatomy at every mesh resolution and on any head with eyes and a mouth.

Each side of a line carries a roll (the bulge of section 5) of its own width; a width of 0 means no
roll on that side, so that parallel lines share the roll between them (forehead, crow's feet)
instead of doubling it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim.model import FaceMesh
from sim.rowmath import norm3

FloatArray = np.ndarray

REFERENCE_IPD = 6.2  # cm, eye centre to eye centre on the reference face the offsets are given on


@dataclass(frozen=True, eq=False)
class WrinkleLine:
    """One expressive wrinkle of a face's mask.

    points:    (K, 2) float64, frontal (x, y) cm of this face, in order along the line. The line's
               "+" side is to the left of its direction seen from the front (up for a line drawn
               towards the face's left, +X).
    muscles:   channel names whose contraction compresses the skin across the line.
    width_minus, width_plus: cm, width of the roll on each side (0: no roll on that side).
    asym_minus, asym_plus:   whether that roll is asymmetric (crest leaning to the furrow; seed 003
               section 5.2, nasolabial folds), read from its own arc-length table.
    emphasis:  the paper's per-wrinkle coefficient multiplying the surplus skin (1 = as tabulated).
    furrow:    depth of the microfurrow along the line, as a fraction of the crest height of its
               rolls (section 2: the microfurrow "draws" the wrinkle).
    """

    name: str
    points: FloatArray
    muscles: tuple[str, ...]
    width_minus: float
    width_plus: float
    asym_minus: bool = False
    asym_plus: bool = False
    emphasis: float = 1.0
    furrow: float = 0.5

    def to_dict(self) -> dict:
        """Plain JSON-able form, for rig files."""
        return {
            "name": self.name,
            "points": np.asarray(self.points).tolist(),
            "muscles": list(self.muscles),
            "width_minus": self.width_minus,
            "width_plus": self.width_plus,
            "asym_minus": self.asym_minus,
            "asym_plus": self.asym_plus,
            "emphasis": self.emphasis,
            "furrow": self.furrow,
        }

    @staticmethod
    def from_dict(data: dict) -> "WrinkleLine":
        """Inverse of `to_dict`; KeyError / ValueError on a malformed entry."""
        pts = np.asarray(data["points"], dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
            raise ValueError(f"wrinkle line {data.get('name')!r}: points must be (K>=2, 2)")
        return WrinkleLine(
            name=str(data["name"]),
            points=pts,
            muscles=tuple(str(m) for m in data["muscles"]),
            width_minus=float(data["width_minus"]),
            width_plus=float(data["width_plus"]),
            asym_minus=bool(data.get("asym_minus", False)),
            asym_plus=bool(data.get("asym_plus", False)),
            emphasis=float(data.get("emphasis", 1.0)),
            furrow=float(data.get("furrow", 0.5)),
        )


@dataclass(frozen=True)
class _Spec:
    """A reference line: anchor name, offsets (lateral dx, up dy) in reference cm, side pattern."""

    name: str
    anchor: str
    offsets: tuple[tuple[float, float], ...]
    muscles: tuple[str, ...]  # "{s}" is replaced by the side suffix for paired lines
    width_minus: float
    width_plus: float
    paired: bool = True
    asym_minus: bool = False
    asym_plus: bool = False
    emphasis: float = 1.0
    furrow: float = 0.5


_FRONTALIS = ("frontalis_inner_l", "frontalis_inner_r", "frontalis_outer_l", "frontalis_outer_r")
_EYE = ("orbicularis_oculi_{s}", "zygomaticus_major_{s}")


def _forehead(k: int, dy: float, below: float, above: float) -> _Spec:
    # the lines droop a little towards the temples
    xs = np.linspace(-4.4, 4.4, 9)
    offs = tuple((float(x), float(dy - 0.35 * (x / 4.6) ** 2)) for x in xs)
    return _Spec(f"forehead_{k}", "eyes_mid", offs, _FRONTALIS, below, above, paired=False)


def _ray(name: str, degrees: float, r0: float, minus: float, plus: float) -> _Spec:
    a = np.radians(degrees)
    offs = tuple((float(r * np.cos(a)), float(r * np.sin(a))) for r in (r0, 1.25, 1.9))
    return _Spec(name, "eye_outer", offs, _EYE, minus, plus, emphasis=0.9)


# Lines drawn on the face's left (+X) with dx > 0 away from the midline; paired lines are mirrored.
# Where the default face's builder lays vertex rows along a wrinkle (sim.face.chart), the line
# follows that row, so each furrow has vertices on it and rolls have rows to rise on.
REFERENCE_MASK: tuple[_Spec, ...] = (
    # horizontal forehead lines; the rolls lie between consecutive lines
    _forehead(1, 3.08, 0.45, 1.0),
    _forehead(2, 4.08, 0.0, 1.0),
    _forehead(3, 5.08, 0.0, 0.6),
    # vertical glabellar lines (corrugators draw the brows together); drawn upwards, so "+" is
    # medial on the left and lateral on the right: the left line carries the roll between the two
    _Spec("glabella_vertical_l", "eyes_mid", ((0.6, 0.78), (0.62, 1.58), (0.68, 2.38)),
          ("corrugator_l", "corrugator_r", "procerus"), 0.4, 1.25, paired=False, emphasis=1.2),
    _Spec("glabella_vertical_r", "eyes_mid", ((-0.6, 0.78), (-0.62, 1.58), (-0.68, 2.38)),
          ("corrugator_l", "corrugator_r", "procerus"), 0.0, 0.4, paired=False, emphasis=1.2),
    # oblique glabellar lines through the inner brow heads; the roll medial to them is the
    # vertical line's
    _Spec("glabella_oblique", "eyes_mid", ((1.05, 0.95), (1.41, 1.5), (1.75, 2.2)),
          ("corrugator_{s}", "procerus"), 0.5, 0.0),
    # nasal-root line: procerus pulls the glabella down, compressing the skin at the nasion
    _Spec("nasal_root", "eyes_mid", ((-0.8, 0.42), (0.0, 0.36), (0.8, 0.42)),
          ("procerus", "corrugator_l", "corrugator_r"), 0.3, 0.3, paired=False),
    # crow's feet fanning from the outer eye corner (drawn outwards: "+" is up); rolls between
    _ray("crows_foot_upper", 20.0, 0.75, 0.4, 0.35),
    _ray("crows_foot_middle", 0.0, 0.6, 0.4, 0.0),
    _ray("crows_foot_lower", -20.0, 0.75, 0.35, 0.0),
    # lower-lid line along the second ring of rows under the lid (drawn outwards, "+" is up)
    _Spec("lower_lid", "eye_center", ((-1.28, -0.57), (-0.64, -0.91), (0.0, -1.08), (0.64, -0.96),
                                      (1.28, -0.55)),
          (*_EYE, "orbicularis_oculi_lid_{s}"), 0.3, 0.25, emphasis=0.8),
    # nasolabial fold from above the nose wing to beside the mouth corner; drawn downwards, so
    # "+" is lateral on the left: the large cheek roll there is asymmetric (section 5.2)
    _Spec("nasolabial", "mouth_corner", ((-0.7, 3.05), (-0.29, 2.54), (0.06, 1.93), (0.34, 1.22),
                                         (0.55, 0.41), (0.7, -0.5)),
          ("levator_labii_{s}", "levator_labii_alaeque_nasi_{s}", "zygomaticus_major_{s}",
           "zygomaticus_minor_{s}", "levator_anguli_oris_{s}"),
          0.3, 0.85, asym_plus=True, emphasis=1.0, furrow=0.3),
    # marionette line from below the mouth corner towards the jaw
    _Spec("marionette", "mouth_corner", ((0.4, -0.55), (0.5, -1.6), (0.6, -2.8)),
          ("depressor_anguli_oris_{s}",), 0.35, 0.35),
    # perioral lines: short vertical lines above the upper and below the lower lip. The builder
    # lays a row on each and flank rows halfway between neighbours, so, as on the forehead, each
    # line carries the roll on its medial side (up to the next line in) and the outermost one
    # also the lateral roll. Upper lines are drawn upwards ("+" medial on the left), lower ones
    # downwards ("+" lateral on the left).
    *(
        _Spec(f"lip_upper_{i}", "mouth_center", ((x, 0.62), (x + 0.05, 1.15)),
              ("orbicularis_oris",), lateral, medial, emphasis=0.8)
        for i, (x, lateral, medial) in enumerate(((0.45, 0.0, 0.45), (0.95, 0.0, 0.5), (1.45, 0.5, 0.5)), start=1)
    ),
    *(
        _Spec(f"lip_lower_{i}", "mouth_center", ((x, -0.78), (x + 0.05, -1.18)),
              ("orbicularis_oris",), medial, lateral, emphasis=0.8)
        for i, (x, medial, lateral) in enumerate(((0.5, 0.5, 0.6), (1.1, 0.0, 0.6)), start=1)
    ),
    # chin crease (mentolabial sulcus): mentalis pushes the chin boss up into it
    _Spec("chin_crease", "mouth_center",
          tuple((float(x), float(-1.55 + 0.25 * (x / 1.9) ** 2)) for x in np.linspace(-1.8, 1.8, 7)),
          ("mentalis", "depressor_labii_l", "depressor_labii_r"), 0.5, 0.35, paired=False),
)


def face_anchors(mesh: FaceMesh) -> tuple[dict[str, FloatArray], float]:
    """Characteristic points (frontal (x, y) cm, left side) and the face's scale against the
    reference face. Derived from the eye and mouth loops only, so every FaceMesh has them."""
    v = mesh.vertices
    ec = np.asarray(mesh.eye_centers, dtype=np.float64)
    scale = norm3(ec[0] - ec[1]) / REFERENCE_IPD
    mid = 0.5 * (ec[0, :2] + ec[1, :2])
    eye = v[np.asarray(mesh.eye_loops[0])][:, :2]
    mouth = v[np.asarray(mesh.mouth_loop)][:, :2]
    return {
        "eyes_mid": mid,
        "eye_center": ec[0, :2],
        "eye_outer": eye[np.argmax(eye[:, 0])],
        "mouth_corner": mouth[np.argmax(mouth[:, 0])],
        "mouth_center": np.array([mid[0], float(mouth[:, 1].mean())]),
    }, scale


def _mirror_anchor(anchors: dict[str, FloatArray], name: str) -> FloatArray:
    p = anchors[name].copy()
    p[0] = 2.0 * anchors["eyes_mid"][0] - p[0]
    return p


def default_mask(mesh: FaceMesh) -> tuple[WrinkleLine, ...]:
    """The reference mask laid out on `mesh`: one WrinkleLine per line and side."""
    anchors, s = face_anchors(mesh)
    lines: list[WrinkleLine] = []
    for spec in REFERENCE_MASK:
        sides = (("l", 1.0), ("r", -1.0)) if spec.paired else (("", 1.0),)
        for suffix, sign in sides:
            base = anchors[spec.anchor] if sign > 0 else _mirror_anchor(anchors, spec.anchor)
            pts = np.array([base + s * np.array([sign * dx, dy]) for dx, dy in spec.offsets])
            line = WrinkleLine(
                name=f"{spec.name}_{suffix}" if suffix else spec.name,
                points=pts,
                muscles=tuple(m.replace("{s}", suffix) for m in spec.muscles),
                width_minus=s * spec.width_minus,
                width_plus=s * spec.width_plus,
                asym_minus=spec.asym_minus,
                asym_plus=spec.asym_plus,
                emphasis=spec.emphasis,
                furrow=spec.furrow,
            )
            if sign < 0:  # mirroring flips which side is "+": swap so medial/lateral is kept
                line = replace(
                    line,
                    width_minus=line.width_plus,
                    width_plus=line.width_minus,
                    asym_minus=line.asym_plus,
                    asym_plus=line.asym_minus,
                )
            lines.append(line)
    return tuple(lines)
