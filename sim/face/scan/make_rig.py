"""How the scanned head's shipped rig (`ict_rig.npz`) is made: the reference face's rig
transferred onto the generic head's skin (`sim.face.transfer`), carried back into the scan's frame,
with the scan's own jaw weights (from its `jawOpen`), eyeballs and the skin under the chin free, its own
pucker (`pucker_ring`), the nose wing's slip of AU9's muscle (`ala_slip`), the puffed air's pressure over
the whole vestibule (`puff_vestibule`), the lips' free margins turned in by the pars marginalis
(`roll_margins`), the infraorbital triangle pushed out by the upper lip's elevators (`levator_bulge`),
the upper lip's shrug turned up (`shrug_up`), and the muscles made stronger for the scan's stiffer skin (`sim.face.scan.rig`). The transfer runs linear
algebra whose last bits follow the BLAS kernel, so it is run once and its result shipped; the
application never runs it. Remake the file with `python -m sim.face.scan.make_rig`; `--ala-slip`
adds the nose wing's slip to the file as it is (every fitted field kept), `--levator-bulge` the
infraorbital triangle's bulge (`levator_bulge`), `--shrug-up` the upper pars peripheralis turned
up (`shrug_up`), `--lip-lift` the lips' lift,
`--puff-vestibule` the puff's pressure over the vestibule, `--roll-margins` the rolls' margins, `--roll-sulcus` the lower lip's
turning, `--mentalis-pout` the mentalis' pout, `--platysma` the platysma's sheet (`platysma`). The
jaw's hinge and the skin's jaw weights are fitted to the scan's jaw shapes by
`python -m sim.face.scan.jaw_fit`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from sim.build import vertex_normals
from sim.face.scan.anatomy import load_landmarks, skin_layout
from sim.face.scan.data import PARTS, scan_data
from sim.face.scan.rig import FORCE, FORCE_OF, RIG_FILE, _lid_sphere, _r, scan_points
from sim.model import FaceMesh, FaceRig, LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle


class _Back:
    """The inverse of the transfer's similarity: points, directions and lengths back to the scan."""

    def __init__(self, similarity) -> None:  # type: ignore[no-untyped-def]
        self.s = similarity

    def point(self, p: np.ndarray) -> np.ndarray:
        return _r(self.s.invert(np.asarray(p, float)))

    def direction(self, d: np.ndarray) -> np.ndarray:
        v = np.asarray(d, float) @ self.s.rotation
        return _r(v / np.linalg.norm(v))

    def length(self, x: float) -> float:
        return float(_r(x / self.s.scale))

    def muscle(self, m: Muscle) -> Muscle:
        if isinstance(m, LinearMuscle):
            return LinearMuscle(m.name, self.point(m.attachment), self.point(m.insertion), self.length(m.radius),
                                float(_r(m.angle)), float(_r(m.eta)), float(_r(m.scale)))
        if isinstance(m, SphincterMuscle):
            return SphincterMuscle(m.name, self.point(m.center), self.direction(m.major_axis),
                                   self.direction(m.minor_axis), self.length(m.a), self.length(m.b), float(_r(m.scale)))
        if isinstance(m, PatchMuscle):  # a zero direction (a pressure along the normal) stays zero
            d = self.direction(m.direction) if np.any(m.direction) else np.zeros(3)
            return PatchMuscle(m.name, self.point(m.center), _r(np.asarray(m.semi_axes, float) / self.s.scale), d,
                               float(_r(m.scale)))
        assert isinstance(m, SheetMuscle)
        return SheetMuscle(m.name, self.point(m.attach1), self.point(m.attach2), self.point(m.insert1),
                           self.point(m.insert2), self.length(m.length), self.length(m.width), float(_r(m.eta)),
                           float(_r(m.scale)))

    def wrinkle(self, line, skin: np.ndarray, project_skin: np.ndarray):  # type: ignore[no-untyped-def]
        """A wrinkle line's frontal points: each put on the skin (the nearest skin vertex in the
        frontal plane of the project frame gives its depth), carried back, frontal again."""
        from dataclasses import replace

        from scipy.spatial import cKDTree

        pts = np.asarray(line.points, float)
        _, near = cKDTree(project_skin[:, :2]).query(pts)
        p3 = np.column_stack([pts, project_skin[near, 2]])
        back = self.s.invert(p3)
        scale = 1.0 / self.s.scale
        return replace(line, points=_r(back[:, :2]), width_minus=float(_r(line.width_minus * scale)),
                       width_plus=float(_r(line.width_plus * scale)))


def _rigid_fit(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t with b ~ R a + t, least squares (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, cb - rot @ ca


def jaw_weights(points: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """(N,) how much each skin vertex follows the mandible, read off the scan's own `jawOpen`: the
    share of the lower teeth's rigid motion (fitted) that the vertex makes, clipped to [0, 1]. The
    transfer's weights cannot tell the upper lip's line from the lower one's (0.8 mm apart)."""
    from sim.face.scan.dressing import TEETH_SPLIT
    from sim.face.scan.data import PARTS

    delta = scan_data().expression("jawOpen")
    lower = np.arange(TEETH_SPLIT, PARTS["teeth"][1])
    rot, t = _rigid_fit(points[lower], points[lower] + delta[lower])
    p = points[skin]
    rigid = p @ rot.T + t - p
    w = np.einsum("ij,ij->i", delta[skin], rigid) / np.maximum(np.einsum("ij,ij->i", rigid, rigid), 1e-12)
    return np.clip(w, 0.0, 1.0)


def under_chin(rest: np.ndarray, triangles: np.ndarray, chin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool twice: the skin under the chin (its normal pointing down, 3 mm or more below the
    chin landmark), and of it the part within one ring of the mask's border."""
    normal = vertex_normals(rest, triangles)
    under = (normal[:, 1] < -0.5) & (rest[:, 1] < chin[1] - 0.3)
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
                              axis=1), axis=0, return_counts=True)
    border = np.zeros(len(rest), bool)
    border[edges[0][edges[1] == 1].ravel()] = True
    ring = border.copy()
    ring[edges[0][border[edges[0][:, 0]] | border[edges[0][:, 1]]].ravel()] = True
    return under, under & ring


def held_skin(held: np.ndarray, rest: np.ndarray, triangles: np.ndarray, chin: np.ndarray) -> np.ndarray:
    """The held skin: the transfer's (the mask's border) and under the chin the border's first ring;
    the rest of the skin under the chin is free. It was held (following the jaw by its weights)
    while, squeezed between the chin and the neck as the jaw opened, it buckled (0.6-1.9 cm2 at
    jaw = 1); the skin's thickness terms (`sim.antifold`) keep it smooth now (0.002 cm2), and held
    it could not follow the chin pushed up by the mentalis, which carries 0.57-0.68 of the scanned
    mouthPress' and mouthShrugLower's motion (docs/scan-face.md, "The lips' contacts ...")."""
    under, ring = under_chin(rest, triangles, chin)
    return (held | under) & ~(under & ~ring)


def _stronger(m: Muscle, channel: str) -> Muscle:
    from dataclasses import replace

    base = channel[:-2] if channel.endswith(("_l", "_r")) else channel
    return replace(m, scale=float(_r(m.scale * FORCE_OF.get(base, FORCE))))


def transferred_rig(weights: np.ndarray | None = None, name: str = "ict") -> FaceRig:
    """The scanned head's rig made by the transfer (5-10 s), for an identity (None: generic)."""
    from sim.face import default_rig
    from sim.face.transfer.landmarks import LandmarkFile
    from sim.face.transfer.meshfile import HeadMesh
    from sim.face.transfer.pipeline import transfer_rig

    points = scan_points(weights)
    layout = skin_layout()
    skin = layout.vertices
    local = {int(s): i for i, s in enumerate(skin)}
    landmarks = {k: local[v] for k, v in load_landmarks().items()}
    head = HeadMesh(f"<{name} scan>", points[skin], layout.triangles, np.arange(len(skin)))
    tr = transfer_rig(default_rig(1), head, LandmarkFile(f"<{name} landmarks>", landmarks), name=name)
    m = tr.rig.mesh
    if len(m.vertices) != len(skin):
        raise RuntimeError("the scan's skin lost vertices in the transfer")
    back = _Back(tr.similarity)
    centres, radii = [], []
    for part, loop in zip(("eyeball_l", "eyeball_r"), m.eye_loops):
        lo, hi = PARTS[part]
        c, r = _lid_sphere(points[lo:hi])
        centres.append(c)
        radii.append(r)
    rest = points[skin]
    mesh = FaceMesh(
        vertices=rest.copy(), triangles=layout.triangles.copy(), landmarks=dict(m.landmarks),
        held=held_skin(np.asarray(m.held, bool), rest, layout.triangles, rest[landmarks["chin"]]),
        jaw_weight=_r(jaw_weights(points, skin)),
        jaw_pivot=back.point(m.jaw_pivot), jaw_axis=back.direction(m.jaw_axis),
        eye_centers=_r(np.array(centres)), eye_radius=float(_r(min(radii))),
        eye_loops=(np.asarray(m.eye_loops[0]), np.asarray(m.eye_loops[1])), mouth_loop=np.asarray(m.mouth_loop),
        regions={k: np.asarray(v, bool) for k, v in m.regions.items()}, uv=None if m.uv is None else _r(m.uv))
    muscles = {ch: tuple(_stronger(back.muscle(p), ch) for p in parts) for ch, parts in tr.rig.muscles.items()}
    wrinkles = tuple(back.wrinkle(w, skin, m.vertices) for w in tr.rig.wrinkles)
    return FaceRig(mesh=mesh, muscles=muscles, wrinkles=wrinkles, name=name)




#: the pucker on the scanned head (ARKit mouthPucker, AU18: the `incisivus` channel). The procedural
#: face's incisivi (two lines from beside the lips' middle to the corners, 2.6 cm wide on the scan)
#: and its forward patch over the lips' margins crumpled the scan's lips: the lines gathered the skin
#: towards two points (creases from the nose to the lip) and the patch pushed the red margins out
#: until they everted apart over the teeth (3 mm), while the scan carries the skin from the nose to
#: below the lower lip 7-8 mm forward with the lips closed. On the scan the lines keep
#: PUCKER_LINES of their force (the corners still drawn in), the patch goes, and a ring as the lips'
#: sphincter (its ellipse) pushes the lips' skin forward, strongest at the ring and nothing at the
#: margins, and draws it in by 1/PUCKER_PROTRUDE of that (docs/scan-face.md, "The pucker").
PUCKER_LINES = 0.3
PUCKER_RING = 2.0 / 3.0  # the ring's pull in units of the sphincter's own (orbicularis_oris)
PUCKER_PROTRUDE = 6.0


def pucker_ring(rig: FaceRig) -> FaceRig:
    """The rig with the scan's pucker (`PUCKER_*`) in place of the transferred one's: the
    incisivus channel's lines weaker, its patch replaced by a protruding ring."""
    from dataclasses import replace

    oris = next(m for m in rig.muscles["orbicularis_oris"] if isinstance(m, SphincterMuscle))
    lines = tuple(replace(m, scale=float(_r(m.scale * PUCKER_LINES)))
                  for m in rig.muscles["incisivus"] if isinstance(m, LinearMuscle))
    ring = replace(oris, name="incisivus_ring", scale=float(_r(oris.scale * PUCKER_RING)), protrude=PUCKER_PROTRUDE)
    return replace(rig, muscles={**rig.muscles, "incisivus": (*lines, ring)})


#: the levator labii superioris alaeque nasi's slip into the nose wing (AU9's channel). The muscle
#: arises on the frontal process of the maxilla and splits as it descends: a medial slip into the
#: perichondrium and skin over the lateral crus of the major alar cartilage, a lateral slip into the
#: upper lip, where it blends with the levator labii superioris and the orbicularis oris; the medial
#: slip raises the nose wing with the lip and dilates the nostril (Gray's Anatomy, 41st ed., the
#: muscles of the face; Park and Hur 2024, Int J Morphol 42:35, dissecting 40 hemifaces: the muscle
#: 5.0 +- 2.4 mm wide at the wing's middle, its fibres shared about equally between the wing and the
#: lip in a third, more into the wing in 28 %, more into the lip in 40 %). The transferred channel is one line of pull aimed beside the ala, which
#: the fitted insertion gain (`FaceRig.insertion`) moved onto the cheek and the lip (0.04-0.26 on the
#: ala, 2-3 on the cheek beside it): under disgust the lip rose over a nose base left behind and the
#: nostrils were squeezed to slits, where the scan lifts and flares the wings. The slip is a second
#: line from the same origin to the ala's lateral wall (ALA_INSERTION, in the scan's frame, cm),
#: reaching ALA_REACH past it within ALA_ANGLE of its axis, its force ALA_FORCE of the channel's line
#: (the fitted gain over the ala applies to it too). Applied to the shipped rig by
#: `python -m sim.face.scan.make_rig --ala-slip` (it replaces a slip the rig already has).
ALA_INSERTION = (1.3, -0.2, 11.9)
ALA_REACH = 0.6
ALA_ANGLE = 0.15
ALA_FORCE = 6.5
ALA_SHIFT = (0.5, 0.0, 1.2)


def ala_slip(rig: FaceRig, insertion: tuple[float, float, float] = ALA_INSERTION, reach: float = ALA_REACH,
             angle: float = ALA_ANGLE, force: float = ALA_FORCE, shift: tuple[float, float, float] = ALA_SHIFT) -> FaceRig:
    """The rig with the levator labii superioris alaeque nasi's slip into the nose wing (`ALA_*`)
    added to both sides' channels, mirrored for the right; any slip it had is replaced."""
    from dataclasses import replace

    muscles = dict(rig.muscles)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        ch = f"levator_labii_alaeque_nasi_{side}"
        parts = tuple(m for m in muscles[ch] if not m.name.endswith("_ala"))
        line = next(m for m in parts if isinstance(m, LinearMuscle))
        ins = _r(np.array(insertion, float) * np.array([sign, 1.0, 1.0]))
        origin = _r(line.attachment + np.array(shift, float) * np.array([sign, 1.0, 1.0]))
        length = float(np.linalg.norm(ins - origin))
        slip = LinearMuscle(f"{ch}_ala", origin, ins, float(_r(length + reach)), float(_r(angle)),
                            line.eta, float(_r(line.scale * force)))
        muscles[ch] = (*parts, slip)
    return replace(rig, muscles=muscles)


#: The infraorbital triangle pushed out by the upper lip's elevators (AU9's and AU10's channels). The
#: levator labii superioris and its alar head lie under the medial cheek's fat (the nasolabial fat
#: compartment, lateral to the fold); contracting, each muscle's belly shortens and thickens and the fat
#: over it is bunched upwards against the fold, so the skin between the nose's side, the lower lid
#: and the top of the nasolabial furrow bulges outwards: FACS describes AU9 and AU10 both raising the
#: infraorbital triangle and deepening the furrow's upper part (Ekman, Friesen and Hager, FACS
#: manual 2002). A line of pull can only slide the skin over the curved face: settled, the transferred
#: channels carried that skin 0.8-0.9 mm inwards where the scan's noseSneer and mouthUpperUp move it
#: 3.9-4.3 mm outwards (their largest error along the normal, 4.9-5.1 mm, centred 1.8-2.4 cm off the
#: midline beside the wing). A pressure patch per side (along the skin's outward normal: the bulge
#: of the tissue beneath) on both channels, centred LEVATOR_BULGE_CENTRE (the scan's frame, cm,
#: mirrored for the right), its semi-axes LEVATOR_BULGE_AXES, its density LEVATOR_BULGE_FORCE times
#: the channel's own line's scale (the channel's fitted insertion gain scales it as it scales the
#: line). Applied to the shipped rig by `python -m sim.face.scan.make_rig --levator-bulge` (it
#: replaces a bulge the rig already has; docs/scan-face.md, "The infraorbital triangle's bulge").
LEVATOR_BULGE_CENTRE = (2.6, 0.5, 10.0)
LEVATOR_BULGE_AXES = (1.0, 1.0, 1.0)
LEVATOR_BULGE_FORCE = 2.0
LEVATOR_BULGE_CHANNELS = ("levator_labii_alaeque_nasi", "levator_labii")


def levator_bulge(rig: FaceRig, centre: tuple[float, float, float] = LEVATOR_BULGE_CENTRE,
                  axes: tuple[float, float, float] = LEVATOR_BULGE_AXES, force: float = LEVATOR_BULGE_FORCE) -> FaceRig:
    """The rig with the infraorbital triangle's bulge (`LEVATOR_BULGE_*`) added to both sides' channels
    of the upper lip's two elevators, mirrored for the right; any bulge they had is replaced."""
    from dataclasses import replace

    muscles = dict(rig.muscles)
    for base in LEVATOR_BULGE_CHANNELS:
        for side, sign in (("l", 1.0), ("r", -1.0)):
            ch = f"{base}_{side}"
            parts = tuple(m for m in muscles[ch] if not m.name.endswith("_bulge"))
            line = next(m for m in parts if isinstance(m, LinearMuscle))
            c = _r(np.array(centre, float) * np.array([sign, 1.0, 1.0]))
            bulge = PatchMuscle(f"{ch}_bulge", c, _r(np.array(axes, float)), np.zeros(3), float(_r(line.scale * force)))
            muscles[ch] = (*parts, bulge)
    return replace(rig, muscles=muscles)


#: The upper lip's pars peripheralis (its channel drives ARKit mouthShrugUpper, and with the lower
#: one the funneler AU22 and mouthClose) is one patch over the upper lip's skin and red part, pushing
#: it along a fixed direction. The transferred one pushed half up and half forward (0, 0.70, 0.72):
#: settled under the scan's mouthShrugUpper the red lip went 1.9 mm forward where the scan's goes 0.7-1.2
#: and the skin above it only 1.8-3.1 mm up (the scan's 3.5-5.1: the upper lip shrugged up against
#: the nose's base, carrying the columella's base 3 mm with it). Turned up along the lip's own
#: surface (SHRUG_DIRECTION, unit once normalised; fitted by settling the shapes that drive the
#: channel, docs/scan-face.md, "The infraorbital triangle's bulge"). Applied to the shipped rig by
#: `python -m sim.face.scan.make_rig --shrug-up`.
SHRUG_DIRECTION = (0.0, 1.0, 0.2)


def shrug_up(rig: FaceRig, direction: tuple[float, float, float] = SHRUG_DIRECTION) -> FaceRig:
    """The rig with the upper pars peripheralis' patch pushing along `direction` (normalised)."""
    from dataclasses import replace

    ch = "orbicularis_oris_peripheralis_upper"
    d = np.array(direction, float)
    parts = tuple(replace(m, direction=_r(d / np.linalg.norm(d))) if isinstance(m, PatchMuscle) else m
                  for m in rig.muscles[ch])
    return replace(rig, muscles={**rig.muscles, ch: parts})


#: the closed lips lifted and carried forward (the `lip_lift` channel, ARKit mouthClose; placed on the
#: procedural face by `sim.face.mouth_actions`). The scan's mouthClose alone lifts the lower lip's
#: middle 38 mm and carries it 17 mm forward, the mouth's corners 15 mm up, the chin 5.5 mm up: the
#: lips closing over a jaw opened as far as its jawOpen, made to be added to it. Our lips cannot pass
#: through each other, so the lower lip's own elevators (the mentalis at its base, the marginal
#: orbicularis rolling it) lift both lips as one, the upper riding on the lower, and push the lower
#: lip forward. Two patches of skin, without the channel's fitted insertion (it has none), centred
#: below the lower lip's middle (the offsets, cm, straight down) and as wide as the modioli and
#: more (a narrower lift sheared the corners and turned their skin over): one pushing up over
#: both lips (LIP_LIFT_UP, dyn/cm^2 at its centre), one pushing forward over the lower lip and
#: the skin below it (LIP_LIFT_FORWARD). Fitted by settling the scan's mouthClose with the rest of
#: its map entry (docs/scan-face.md, "mouthClose: the lips lifted"); applied to the shipped rig by
#: `python -m sim.face.scan.make_rig --lip-lift`.
LIP_LIFT_UP = (0.5, (5.0, 0.8, 3.3), 16000.0)  # (offset below the lower lip, semi-axes, force density)
LIP_LIFT_FORWARD = (1.0, (5.0, 1.0, 3.3), 22000.0)


def lip_lift(rig: FaceRig, up: tuple = LIP_LIFT_UP, forward: tuple = LIP_LIFT_FORWARD) -> FaceRig:  # type: ignore[type-arg]
    """The rig with the scan's lips' lift (`LIP_LIFT_*`) as the `lip_lift` channel's parts (any it
    had are replaced)."""
    from dataclasses import replace

    lower = np.asarray(rig.mesh.vertices[rig.mesh.landmarks["lower_lip_center"]], np.float64)
    parts = []
    for name, (drop, semi, scale), direction in (("lip_lift_up", up, (0.0, 1.0, 0.0)),
                                                  ("lip_lift_forward", forward, (0.0, 0.0, 1.0))):
        centre = _r(lower - np.array([0.0, drop, 0.0]))
        parts.append(PatchMuscle(name, centre, _r(np.array(semi, np.float64)), np.array(direction, np.float64),
                                 float(scale)))
    return replace(rig, muscles={**rig.muscles, "lip_lift": tuple(parts)})
#: The air of a puff (AU34, cheek_puff) presses on the whole wall of the mouth's vestibule: the
#: cheeks' buccal wall from the masseter's front edge to the lips' corners, and on across the lips'
#: inside to the midline (the lips sealed, the vestibule is one space from cheek to cheek), between
#: its two fornices (under the cheekbone, above the mandible's lower border). The transferred
#: channel is a pressure over each cheek's middle only (an ellipsoid 5.4 cm across, 6.6 deep,
#: centred 5.2 cm off the midline), so the scan's puffed lips and the skin beside the nose came out
#: half as far as the scan's (docs/scan-face.md, "The lips and the puff"). The pressure patch is
#: grown PUFF_ACROSS times across (to the midline and a little past it, where the two sides' patches
#: overlap on the lips) and PUFF_DEEP times front to back, no taller (the fornices), its peak
#: PUFF_PRESSURE of the transferred one (the same air over more wall). The grown parts are named
#: with PUFF_SUFFIX, so applying it again changes nothing.
PUFF_ACROSS = 2.4
PUFF_DEEP = 2.0
PUFF_PRESSURE = 0.6
PUFF_SUFFIX = "_vestibule"


def puff_vestibule(rig: FaceRig) -> FaceRig:
    """The rig with the cheek_puff channel's pressure patches grown over the vestibule (`PUFF_*`)."""
    from dataclasses import replace

    parts = []
    for m in rig.muscles["cheek_puff"]:
        if isinstance(m, PatchMuscle) and not m.name.endswith(PUFF_SUFFIX):
            grow = np.array([PUFF_ACROSS, 1.0, PUFF_DEEP])
            m = replace(m, name=m.name + PUFF_SUFFIX, semi_axes=_r(np.asarray(m.semi_axes, float) * grow),
                        scale=float(_r(m.scale * PUFF_PRESSURE)))
        parts.append(m)
    return replace(rig, muscles={**rig.muscles, "cheek_puff": tuple(parts)})


#: The pars marginalis runs in the vermilion along each lip's free margin; contracting, it turns
#: the lip in about its own core (AU28, the rolls): the free margin goes into the mouth over the
#: teeth and the vermilion's border follows it to where the margin was (the scan's mouthRollUpper:
#: the upper lip's margin 2.1 mm up and 10.9 back, its border 5 down and 8.4 back; mouthRollLower:
#: the lower margin 12.8 back, its border 9 up and 7.4 back). The transferred channel is one patch
#: over the red lip pushing it all down and back (up and back for the lower lip), so the margin
#: went down with it (-2.3 mm). A second patch per lip on the margin itself (ROLL_MARGIN_*: its
#: centre in the scan's frame, cm, its semi-axes, its direction for the upper lip, mirrored in
#: height for the lower, its force in units of the lip's own patch) turns the margin up and back
#: (down and back), so the two patches together roll the lip (docs/scan-face.md, "The lips and
#: the puff"). Applying it again changes nothing (it replaces a margin the rig already has).
ROLL_MARGIN_UPPER = (0.0, -3.3, 11.0)
ROLL_MARGIN_LOWER = (0.0, -3.42, 11.05)
ROLL_MARGIN_AXES = (2.4, 0.35, 0.8)
ROLL_MARGIN_DIRECTION = (0.0, 0.8, -0.6)
ROLL_MARGIN_FORCE = 1.0


def roll_margins(rig: FaceRig) -> FaceRig:
    """The rig with the pars marginalis' margin patches (`ROLL_MARGIN_*`) added to both lips' channels."""
    from dataclasses import replace

    muscles = dict(rig.muscles)
    for lip, centre, sign in (("upper", ROLL_MARGIN_UPPER, 1.0), ("lower", ROLL_MARGIN_LOWER, -1.0)):
        ch = f"orbicularis_oris_marginalis_{lip}"
        parts = tuple(m for m in muscles[ch] if not m.name.endswith("_margin"))
        own = next(m for m in parts if isinstance(m, PatchMuscle))
        d = np.array(ROLL_MARGIN_DIRECTION, float) * np.array([1.0, sign, 1.0])
        margin = PatchMuscle(f"marginalis_{lip}_margin", _r(np.array(centre, float)), _r(np.array(ROLL_MARGIN_AXES, float)),
                             _r(d / np.linalg.norm(d)), float(_r(own.scale * ROLL_MARGIN_FORCE)))
        muscles[ch] = (*parts, margin)
    return replace(rig, muscles=muscles)


#: The lower lip rolled in turns about its core as a whole (AU28, the lower pars marginalis): as its
#: free margin goes back over the lower teeth, the lip's lower part (the vermilion's border and the
#: skin down to the labiomental sulcus, over the bulk of the orbicularis) swings forward and up
#: and the sulcus fills. The scan's mouthRollLower carries the skin 5-10 mm below the red lip
#: (y -5.0 to -5.7 cm) 8-9 mm up and 3-5 mm forward while the chin's boss below stays; the two
#: patches of the channel (`roll_margins`) push only the red lip and its margin, so ours rose 4-6
#: mm and came 0-1 mm forward there. A third patch on the sulcus (ROLL_SULCUS_*: centre in the
#: scan's frame, cm, semi-axes, direction, force in units of the lip's own patch) pushes it
#: forward (docs/scan-face.md, "The lower lip's turning"). Applying it again changes nothing.
ROLL_SULCUS_CENTRE = (0.0, -5.5, 10.9)
ROLL_SULCUS_AXES = (2.4, 0.8, 1.0)
ROLL_SULCUS_DIRECTION = (0.0, 0.0, 1.0)
ROLL_SULCUS_FORCE = 7500.0 / 8640.0


def roll_sulcus(rig: FaceRig) -> FaceRig:
    """The rig with the lower lip's turning (`ROLL_SULCUS_*`) added to the lower pars marginalis'
    channel (any sulcus part it had is replaced)."""
    from dataclasses import replace

    ch = "orbicularis_oris_marginalis_lower"
    parts = tuple(m for m in rig.muscles[ch] if not m.name.endswith("_sulcus"))
    own = next(m for m in parts if isinstance(m, PatchMuscle))
    sulcus = PatchMuscle("marginalis_lower_sulcus", _r(np.array(ROLL_SULCUS_CENTRE, float)),
                         _r(np.array(ROLL_SULCUS_AXES, float)), np.array(ROLL_SULCUS_DIRECTION, float),
                         float(_r(own.scale * ROLL_SULCUS_FORCE)))
    return replace(rig, muscles={**rig.muscles, ch: (*parts, sulcus)})


#: The mentalis raises the chin's soft tissue and, its two bellies together, pushes the lower lip
#: out and up (the pout of ARKit's mouthShrugLower: the scan's lower red lip 3.5 mm forward and
#: 4.1 up, its margin 2.3 forward; ours, the sheet pushing the chin up, 2.0 and 1.0 forward). A
#: patch over the lower red lip pushing it forward and up (MENTALIS_POUT_*: centre in the scan's
#: frame, cm, semi-axes, direction, force density dyn/cm^2), part of the whole channel only
#: (`sim.build.BOTH_SIDES`): the press' halves of the mentalis (mouthPress) raise the chin on one
#: side without a pout (docs/scan-face.md, "The mentalis' pout"). Applying it again changes nothing.
MENTALIS_POUT_CENTRE = (0.0, -3.9, 11.4)
MENTALIS_POUT_AXES = (2.4, 0.6, 1.0)
MENTALIS_POUT_DIRECTION = (0.0, 0.5, 1.0)
MENTALIS_POUT_FORCE = 5000.0


def mentalis_pout(rig: FaceRig) -> FaceRig:
    """The rig with the mentalis' pout (`MENTALIS_POUT_*`) added to its whole channel (any pout it
    had is replaced)."""
    from dataclasses import replace

    from sim.build import BOTH_SIDES

    name = "mentalis_pout" + BOTH_SIDES
    parts = tuple(m for m in rig.muscles["mentalis"] if m.name != name)
    d = np.array(MENTALIS_POUT_DIRECTION, float)
    pout = PatchMuscle(name, _r(np.array(MENTALIS_POUT_CENTRE, float)), _r(np.array(MENTALIS_POUT_AXES, float)),
                       _r(d / np.linalg.norm(d)), MENTALIS_POUT_FORCE)
    return replace(rig, muscles={**rig.muscles, "mentalis": (*parts, pout)})
#: The platysma (AU21, the `platysma_l/_r` channels; placed on the procedural face by
#: `sim.face.mouth_actions`): a thin sheet in the subcutaneous fat from the skin of the lower face
#: (over the mandible's body from the chin to the masseter's front edge, interlacing with the
#: corner's depressor and the risorius below the modiolus) down over the front of the neck to the
#: chest. Contracting, its facial part draws the jowl's skin out and down over the jaw's border and
#: its cervical part tenses the skin under the chin down towards the chest. The scan shows both:
#: mouthStretch carries the jowl over the jaw's body 2.5 mm out (ours 1.3), jawOpen hangs the skin
#: under the chin 22 mm down (ours 11, it slid back with the chin). Two patches per side (the face's
#: left; the right mirrored, x -> -x): the facial part over the jowl (PLATYSMA_FACE) and the
#: cervical part under the chin, reaching across the midline where the two sides' sheets meet
#: (PLATYSMA_NECK); each (centre cm in the scan's frame, semi-axes cm, direction, force density
#: dyn/cm^2 at the centre): the neck's force swept on the scan's jawOpen (the share ARKit's map
#: gives it) up to what turns no skin over (stronger, the skin under the chin buckled against the
#: held border), the face's on mouthStretch; no tether-anchor field (fitted on jawOpen by
#: `benchmarks/anchor_limits.py --only platysma=1.5` it took 0.241 to 0.241). Applied to the shipped
#: rig by `python -m sim.face.scan.make_rig --platysma` (docs/scan-face.md, "The platysma").
PLATYSMA_FACE = ((4.6, -5.2, 7.0), (2.2, 2.6, 3.0), (0.95, -0.3, 0.0), 1500.0)
PLATYSMA_NECK = ((1.4, -8.4, 6.0), (2.6, 2.0, 2.2), (0.0, -0.95, 0.3), 12000.0)


def platysma(rig: FaceRig, face: tuple = PLATYSMA_FACE, neck: tuple = PLATYSMA_NECK) -> FaceRig:  # type: ignore[type-arg]
    """The rig with the platysma's patches (`PLATYSMA_*`) as the `platysma_l/_r` channels' parts (any
    they had are replaced)."""
    from dataclasses import replace

    muscles = dict(rig.muscles)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        flip = np.array([sign, 1.0, 1.0])
        parts = []
        for part, (centre, semi, direction, scale) in (("face", face), ("neck", neck)):
            d = np.array(direction, np.float64) * flip
            parts.append(PatchMuscle(f"platysma_{part}_{side}", _r(np.array(centre, np.float64) * flip),
                                     _r(np.array(semi, np.float64)), _r(d / np.linalg.norm(d)), float(scale)))
        muscles[f"platysma_{side}"] = tuple(parts)
    return replace(rig, muscles=muscles)


def pack(path: str | Path = RIG_FILE) -> None:
    """Write the generic head's rig as the shipped rig file, keeping the insertion gains and the
    skin's material fitted to the scans (`sim.face.scan.calibrate`, `sim.face.scan.skin_fit`, run
    by `benchmarks/calibrate_scan.py`, which rewrites them) that the file already holds, with the
    lids built on it (`sim.face.scan.lids`)."""
    from dataclasses import replace

    from sim.face.scan.lids import with_lids
    from sim.rig import load_rig, save_rig

    old = load_rig(path) if Path(path).is_file() else None
    made = replace(transferred_rig(), insertion=old.insertion if old else {}, skin=old.skin if old else {},
                   tissue=old.tissue if old else {}, strain=old.strain if old else {},
                   anchor=old.anchor if old else {}, gaze=old.gaze if old else {})
    save_rig(platysma(mentalis_pout(roll_sulcus(shrug_up(levator_bulge(lip_lift(roll_margins(puff_vestibule(
        ala_slip(with_lids(pucker_ring(made))))))))))), path)


#: The steps `python -m sim.face.scan.make_rig --FLAG` adds to the rig file as it is (every fitted
#: field kept), by flag; run on top of the shipped rig in the order benchmarks/anchor_limits.py lists.
ADD_STEPS = {"--ala-slip": ala_slip, "--levator-bulge": levator_bulge, "--shrug-up": shrug_up, "--lip-lift": lip_lift,
             "--puff-vestibule": puff_vestibule, "--roll-margins": roll_margins, "--roll-sulcus": roll_sulcus,
             "--mentalis-pout": mentalis_pout, "--platysma": platysma}


def add_step(step: Callable[[FaceRig], FaceRig], path: str | Path = RIG_FILE) -> None:
    """Write the rig file again with one step (`ADD_STEPS`) applied, everything else as it is."""
    from sim.rig import load_rig, save_rig

    save_rig(step(load_rig(path)), path)


if __name__ == "__main__":
    import sys

    flags = [a for a in sys.argv[1:] if a in ADD_STEPS]
    if flags:
        add_step(ADD_STEPS[flags[0]])
    else:
        pack()
    print(f"wrote {RIG_FILE}")
