"""The face's data: geometry (FaceMesh), rig (FaceRig = mesh + muscles + wrinkles), the compiled
simulation model (FaceModel), the per-step state (FaceState) and the inputs (FaceControl).

Units everywhere in `sim`: centimetres, grams, seconds (forces in dyn = g*cm/s^2). Right-handed,
+Y up, the face looks along +Z, +X is the face's own left. `_l` / `_r` name the face's own sides.

Who fills what:
- `sim.face.builder` builds a `FaceMesh` procedurally (no third-party mesh).
- `sim.muscles` places muscles on a mesh from its landmarks, giving a `FaceRig`.
- `sim.rigfile` saves and loads a `FaceRig` (no pickle), `sim.face.transfer` makes one for another head.
- `sim.build.compile_model(rig)` makes the `FaceModel` the integrator runs: springs, masses, muscle
  influence precomputed from rest geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Union

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray


@dataclass(eq=False)
class FaceMesh:
    """The skin surface and what the rig needs to know about its regions.

    vertices:      (N, 3) float64, cm, rest pose.
    triangles:     (M, 3) int32, counter-clockwise seen from outside (normals point out of the skin).
    landmarks:     name -> vertex index, names as in the project's landmark vocabulary.
    held:          (N,) bool: skin bound to skull/scalp at the boundary (pinned by the integrator).
    jaw_weight:    (N,) float64 in [0, 1]: how rigidly a vertex follows the jaw's rotation.
    jaw_pivot:     (3,) cm, a point on the jaw hinge axis; jaw_axis (3,) unit, rotation axis
                   (positive `jaw` opens the mouth).
    eye_centers:   (2, 3) cm, centres of the eyeballs, row 0 = left (+X), row 1 = right.
    eye_radius:    cm, eyeball radius.
    eye_loops:     two int arrays: vertex indices around each eye opening, in order (left, right).
    mouth_loop:    int array: vertex indices around the mouth opening between the lips, in order.
    regions:       name -> (N,) bool masks (e.g. "upper_lid_l", "lower_lip", "forehead"), optional.
    uv:            (N, 2) float64 or None: the flat parameterisation the mesh was built on (the
                   builder's (u, v) chart), used to lay out wrinkle lines and for rig transfer.
    """

    vertices: FloatArray
    triangles: IntArray
    landmarks: dict[str, int]
    held: np.ndarray
    jaw_weight: FloatArray
    jaw_pivot: FloatArray
    jaw_axis: FloatArray
    eye_centers: FloatArray
    eye_radius: float
    eye_loops: tuple[IntArray, IntArray]
    mouth_loop: IntArray
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    uv: FloatArray | None = None

    def landmark(self, name: str) -> FloatArray:
        """Rest position (3,) of a named landmark."""
        return self.vertices[self.landmarks[name]]


@dataclass(frozen=True, eq=False)
class LinearMuscle:
    """Seed 000 section 3.1. attachment m^A on the skull, insertion m^I in the skin (cm);
    radius R_j (cm), max angle phi_j (rad), strength exponent eta_j, force scale alpha_L (dyn)."""

    name: str
    attachment: FloatArray
    insertion: FloatArray
    radius: float
    angle: float
    eta: float
    scale: float


@dataclass(frozen=True, eq=False)
class SphincterMuscle:
    """Seed 000 section 3.2. centre o (cm), unit axes of the ellipse (major, minor), semi-axes a, b
    (cm), force scale alpha_S (dyn). protrude: the push out of the face (along major x minor) per
    unit of the pull towards the centre, as a ring of fibres squeezing incompressible lips carries
    them forward (a pucker); 0 (the paper's sphincter) for every ring but the pucker's."""

    name: str
    center: FloatArray
    major_axis: FloatArray
    minor_axis: FloatArray
    a: float
    b: float
    scale: float
    protrude: float = 0.0


@dataclass(frozen=True, eq=False)
class SheetMuscle:
    """Seed 000 section 3.3. Attachment line A1-A2, insertion line I1-I2 (cm); zone length L_j and
    width W_j (cm), strength exponent eta_j, force scale alpha_st (dyn)."""

    name: str
    attach1: FloatArray
    attach2: FloatArray
    insert1: FloatArray
    insert2: FloatArray
    length: float
    width: float
    eta: float
    scale: float


@dataclass(frozen=True, eq=False)
class PatchMuscle:
    """A force spread over one region of skin, for the actions a line of pull cannot make: lips
    everted, rolled in, bunched or shifted as a band, cheeks pushed out by the air in the mouth.
    centre (3,) cm and semi-axes (3,) cm of the ellipsoid it acts in (along the face frame's X, Y,
    Z); direction (3,) unit, or zeros for "along the skin's outward normal" (a pressure); force
    density alpha_P (dyn/cm^2) at the centre, fading as cos(d pi/2) to the ellipsoid's surface."""

    name: str
    center: FloatArray
    semi_axes: FloatArray
    direction: FloatArray
    scale: float


Muscle = Union[LinearMuscle, SphincterMuscle, SheetMuscle, PatchMuscle]


SKIN_FIELDS = ("modulus", "support", "tether")  # FaceRig.skin


@dataclass(eq=False)
class FaceRig:
    """Everything needed to simulate one face: its mesh, its muscles (channel name -> one or more
    muscle parts), and its wrinkle lines (filled by `sim.wrinkles`; may be empty).

    insertion: channel name -> (N,) non-negative gain per skin vertex on that channel's force field
    (how densely the muscle inserts into the skin there; its direction of pull is its parts'). A
    channel not named has gain 1 everywhere. Fitted to scanned expressions for the scanned head
    (`sim.face.scan.calibrate`); the procedural face has none.

    skin: per skin vertex (N,) non-negative multipliers of the skin's material where it is not
    uniform: "tether" (its attachment to the tissue beneath, `SkinParams.tether`), "support" (the
    resistance to indentation along the normal, `SkinParams.support`) and "modulus" (the membrane's
    springs, `SkinParams.sheet_modulus` and bending; a spring takes the mean of its two ends'). Real
    skin is held by retaining ligaments in some places and slides over fat pads in others. A key
    not named is 1 everywhere; fitted to scanned expressions for the scanned head
    (`sim.face.scan.skin_fit`); the procedural face has none.

    tissue: named structures of the skin on top of `skin`, each "<field>_<structure>" -> (N,)
    multiplier (1 where the structure is not) of that skin field ("tether", "support", "modulus"):
    "tether_orbital_retaining", the orbicularis retaining ligament tying the skin under the brow
    to the orbital rim; "modulus_lid_fold", the upper lid's skin between the tarsus and the fold,
    folded at rest and stretched only as the lid closes. Built from the scanned head's own geometry
    (`sim.face.scan.lids`), so a refit of `skin` leaves them; the procedural face has none.

    strain: channel name -> (N, 6) active strain per skin vertex (xx, yy, zz, xy, xz, yz): the
    change of the tissue's rest shape as that channel's muscle contracts, per unit value
    (`sim.active_strain`; a spring's rest length changes by the mean of its two ends' strain along
    it, where both ends carry one). Fitted to scanned expressions for the scanned head
    (`sim.face.scan.strain_fit`); a channel not named has none, the procedural face none.

    anchor: channel name -> (N, 3) cm, the displacement of each skin vertex's tether anchor (its
    rest place on the tissue beneath) per unit value: the deep layer the muscle lies in carrying the
    places the skin is tied to (`sim.face.scan.anchor_fit`). The tether being linear, it joins the
    channel's field as the force k_r d. Fitted to scanned expressions for the scanned head; a
    channel not named has none, the procedural face none.

    gaze: "<look>_<side>" (look: in, out, up, down; side: l, r) -> (N, 3) cm, the displacement of
    each skin vertex's tether anchor with that eye turned fully that way: the tissue round the globe
    (Tenon's capsule, the orbital fat, the check ligaments, the lids' retractors) carried by the
    turning eye (`sim.gaze_lids.tissue_fields`; a turn part of the way carries them by the
    sine and versine of its angle). Fitted to the scan's eyeLook shapes for the scanned head
    (`sim.face.scan.gaze_fit`); the procedural face has none.

    integrator: what `sim.integrator.Simulator(method="auto")` runs this face on: "auto" (by the
    work per frame), "rk2" or "implicit". An imported head asks for "implicit", whose fold guard
    keeps a foreign mesh's skin from turning over (`sim.antifold`).

    presets: whose preset intensities the face takes (`sim.facs.preset_face`): "" for its name's
    (the built-in faces), "imported-3" (before it "imported-2", "imported") for a head brought in by
    `sim.face.transfer`."""

    mesh: FaceMesh
    muscles: dict[str, tuple[Muscle, ...]]
    wrinkles: tuple = ()
    name: str = "default"
    insertion: dict[str, np.ndarray] = field(default_factory=dict)
    skin: dict[str, np.ndarray] = field(default_factory=dict)
    integrator: str = "auto"
    presets: str = ""
    tissue: dict[str, np.ndarray] = field(default_factory=dict)
    strain: dict[str, np.ndarray] = field(default_factory=dict)
    anchor: dict[str, np.ndarray] = field(default_factory=dict)
    gaze: dict[str, np.ndarray] = field(default_factory=dict)
