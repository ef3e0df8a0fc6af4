"""Channel values -> ARKit's 52 blendshapes, written as a Live Link Face-style CSV.

The mapping is a documented approximation (see docs/live.md): every one of the 52 shapes has a
channel, but we have muscles ARKit cannot express (zygomaticus minor AU11, levator anguli oris
AU13, age). MouthFunnel is written from the lower lip's eversion and MouthShrugUpper from the
upper's (a funnel everts both), so a pose whose upper lip is everted at least as far as its lower
one, and no further than the shrug's span (`SHAPE_SPAN`) unless exactly as far, comes back as itself. "Left" is the face's own left, the `_l` side of our channels."""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from devices.facestream import ARKIT_NAMES
from puppet.errors import ConfigError
from sim.gaze_lids import eye_yaws

#: The 52 blendshapes in ARKit's order, spelt as the Live Link Face CSV does (PascalCase).
ARKIT_SHAPES = tuple(n[0].upper() + n[1:] for n in ARKIT_NAMES)
ROTATIONS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
             "RightEyeYaw", "RightEyePitch", "RightEyeRoll")

Getter = Callable[[str], float]


def _side(shape: str) -> str:
    return "_l" if shape.endswith("Left") else "_r"


#: Sided shapes (base name without Left/Right) that are one channel of the same side.
SIMPLE_SHAPES = {
    "EyeBlink": "orbicularis_oculi_lid", "EyeWide": "levator_palpebrae", "EyeSquint": "orbicularis_oculi", "CheekSquint": "orbicularis_oculi",
    "NoseSneer": "levator_labii_alaeque_nasi", "MouthSmile": "zygomaticus_major",
    "MouthFrown": "depressor_anguli_oris", "MouthDimple": "buccinator", "MouthStretch": "risorius",
    "MouthLowerDown": "depressor_labii", "MouthUpperUp": "levator_labii", "BrowOuterUp": "frontalis_outer",
}


#: ARKit's mouthClose counts against the jaw's opening (the lips meet at mouthClose = jawOpen); our
#: lip_closure at 1 closes a jaw opened 0.25, so MouthClose = 0.25 lip_closure (and back).
MOUTH_CLOSE_SPAN = 0.25
#: Calibrated against the ICT FaceKit's scanned shapes on the scanned face (benchmarks/scan_match.py;
#: fitted on the simulator's settled poses by benchmarks/map_fit.py): the value of a shape's channel
#: that the shape at 1 stands for. Driven at 1, these channels moved the skin further than the scans
#: (the squint's orbital sphincter pulled the skin round the whole eye in); at these values each is
#: closest to its scan (docs/scan-face.md). browInnerUp drives the inner frontalis to 0.85 (0.55
#: while the muscle lifted the forehead rather than the brows' heads; its anchors, refitted at 0.85,
#: carry the glabella and the brows' heads as the medial fibres do, and the brows raised in full
#: stay within real brows: docs/scan-face.md, "The inner brows and the cheek's squint").
#: jawOpen at 1 opens the jaw 0.8 (the scan's 25.3 degrees of our 31.5 at 1, about the hinge fitted
#: to it: `sim.face.scan.jaw_fit.OPENING_SPAN`, docs/scan-face.md, "The jaw's hinge ...").
#: The export divides by it (a larger channel value writes 1), the import and the map multiply.
SHAPE_SPAN = {"BrowInnerUp": 0.85, "EyeSquint": 0.5, "MouthPress": 0.85, "MouthDimple": 1.0, "MouthLowerDown": 0.8,
              "MouthSmile": 0.55, "EyeWide": 0.7, "MouthShrugUpper": 0.8, "MouthUpperUp": 0.7, "MouthFunnel": 0.4,
              "JawOpen": 0.8}
#: Shapes that also drive other channels, each by a share of the shape (the channel takes the larger
#: of its own shape and the share, as the lids do with the gaze; a channel named without its side is
#: the shape's side, both sides for an unsided shape; "Mouth" is MouthLeft / MouthRight). Fitted on
#: the simulator's settled poses (benchmarks/map_fit.py: Levenberg-Marquardt on the span and every
#: share at once, the shares' L1 cost keeping the few that matter), each kept where the settled
#: shape came closer to its scan by more than 0.01 and its right twin, held out, followed. What they
#: model: pressed lips push the chin's soft tissue up (mentalis), as the scanned mouthPress does;
#: puffed cheeks hold the air behind pursed lips (incisivus), which the scanned cheekPuff carries
#: 13 mm forward, and lift the nose's wings with the lip (the scan's puff lifts the nose 1.3 mm and
#: carries its base 6.6 mm forward); funnelled lips are carried forward by
#: the incisivi and opened by the lower lip's depressor (the scanned mouthFunnel parts the lips
#: 13.5 mm, the lower one 8 mm down, the everting pars peripheralis at 0.4 of full); the lower lip pushed up or rolled in meets the upper one (lip closure, the
#: sphincter); the dimple's buccinator pulls on the modiolus with the corner's elevators; the nose
#: wrinkled brings the orbital orbicularis, the corner's elevator and the brow's head down with it;
#: the smile is the whole modiolus drawn up and back (the corner's elevator, the buccinator and the
#: risorius with the zygomaticus major at 0.55: at 1 alone it draws the corner too far along its own
#: line, and no share helps while it does) with the upper lip lifted (levator labii) and the cheek
#: bunched under the eye (the orbital orbicularis), as the scan's mouthSmile is;
#: the mouth shifted sideways is drawn by that side's zygomaticus and risorius; the stretched
#: corner is drawn down and back with the depressor anguli oris and a trace of the buccinator (the
#: scan's mouthStretch carries the lower lip 1.6 mm down and the jowl out); the lips closed over
#: an open jaw are pushed up by the chin (mentalis) and the corners' elevators; the lips pressed,
#: the lower one pushed up and the lips closed carry the chin's soft tissue forward as a block,
#: which the jaw thrust (jaw_forward) gives where more mentalis would evert the lower lip; the
#: squinting eye's lower lid is lifted by its own palpebral orbicularis (AU7's lower lid
#: tightener; the cheek's squint, AU6, lifts the cheek with a trace of the zygomaticus major, whose
#: upper fibres lie under the malar fat the orbital orbicularis bunches: 0.06, fitted on the
#: anchored rig, where before any share took it further from its scan; 0.1 once the orbital
#: orbicularis' field carried the cheek further, swept on the settled poses). A share is at most
#: the span of the shape that writes its channel back, so a pose exported and streamed back returns
#: as itself. mouthPress' and mouthClose's shares were refitted by hand (a sweep of settled poses)
#: once the skin under the chin was set free: the mentalis then carries it, and at the former
#: shares (0.55, 1.0) lifted it too far (mouthPress 0.88) or turned it over (mouthClose 0.50 cm2);
#: the jaw thrust's shares were swept the same way (mouthClose's kept at 0.3: more came closer
#: still but parted the lips of a spoken "m"; mouthShrugLower's 0.3 -> 0.2 once the jaw's hinge and
#: weights were fitted to the scan, the chin then following the thrust closer). mouthPress and mouthDimple are one-sided, as their
#: scans are: they drive the side's halves of the lips' sphincter and the mentalis
#: (`sim.channels.HALVES`; `share_targets` picks the half for a one-sided shape), their spans and
#: shares fitted again on the settled poses with the halves (docs/scan-face.md, "The press in
#: halves"). The jaw opened tenses the platysma (AU21, both sides at the shape's own weight): its
#: cervical sheet hangs the skin under the chin down with the jaw, as the scan's jawOpen does (22
#: mm; 11 without it, 15 with it), and draws the jowls out (docs/scan-face.md, "The platysma"); the mouth's
#: shapes that reach the jowl (mouthStretch, mouthFrown, mouthLowerDown, mouthPress) came further
#: from their scans with any share of it, so none takes one.
SHAPE_SHARES: dict[str, tuple[tuple[str, float], ...]] = {
    "MouthPress": (("mentalis", 0.64), ("levator_anguli_oris", 0.34), ("jaw_forward", 0.07)),
    "CheekPuff": (("incisivus", 1.0), ("levator_labii_alaeque_nasi", 0.25)),
    "MouthFunnel": (("incisivus", 0.65), ("depressor_labii", 0.7), ("levator_labii", 0.15)),
    "MouthShrugLower": (("lip_closure", 0.25), ("orbicularis_oris", 0.35), ("zygomaticus_major", 0.15),
                        ("incisivus", 0.25), ("jaw_forward", 0.2)),
    "MouthRollLower": (("lip_closure", 0.4),),
    "MouthRollUpper": (("risorius", 0.2), ("orbicularis_oris", 0.6)),
    "MouthStretch": (("buccinator", 0.1), ("depressor_anguli_oris", 0.25)),
    "MouthSmile": (("levator_anguli_oris", 1.0), ("buccinator", 0.5), ("risorius", 0.45), ("levator_labii", 0.35),
                   ("orbicularis_oculi", 0.2)),
    "MouthDimple": (("levator_anguli_oris", 0.57), ("zygomaticus_major", 0.11), ("mentalis", 0.15), ("orbicularis_oris", 0.85)),
    "MouthLowerDown": (("depressor_anguli_oris", 0.2),),
    "BrowDown": (("orbicularis_oculi", 0.15),),
    "EyeSquint": (("orbicularis_oculi_lower_lid", 0.1),),
    "CheekSquint": (("zygomaticus_major", 0.1),),
    "NoseSneer": (("orbicularis_oculi", 0.55), ("levator_anguli_oris", 0.4), ("corrugator", 0.35)),
    "MouthShrugUpper": (("levator_labii", 0.2),),
    "MouthUpperUp": (("levator_labii_alaeque_nasi", 0.25),),
    "Mouth": (("zygomaticus_major", 0.5), ("risorius", 0.25), ("levator_labii_alaeque_nasi", 0.2), ("incisivus", 0.35)),
    "JawOpen": (("platysma", 1.0),),
    "MouthClose": (("mentalis", 0.3), ("levator_anguli_oris", 0.3), ("orbicularis_oris_peripheralis_upper", 0.8),
                   ("zygomaticus_major", 0.3), ("jaw_forward", 0.3)),
}
#: The lips lifted and carried forward as one (`lip_lift`) follow mouthClose itself, not the
#: closure's span: the channel at 1 is the scan's mouthClose at 1 (the lower lip 17 mm up and 5.5
#: forward on the scanned head), so over a jaw opened w the shape w lifts them by w of it (tied to
#: the span, a spoken "m", mouthClose 0.1, lifted the lips 6.5 mm where the scan's shape gives 3.8,
#: docs/scan-face.md "mouthClose: the lips lifted"). The export writes MouthClose as the larger of
#: the closure over its span and the lift.
MOUTH_CLOSE_LIFT = "lip_lift"
#: Shapes that are one channel each (besides the sided ones above).
ONE_CHANNEL = {
    "JawForward": "jaw_forward", "MouthClose": "lip_closure", "MouthPucker": "incisivus",
    "MouthFunnel": "orbicularis_oris_peripheralis_lower", "MouthShrugUpper": "orbicularis_oris_peripheralis_upper",
    "MouthRollUpper": "orbicularis_oris_marginalis_upper", "MouthRollLower": "orbicularis_oris_marginalis_lower",
    "MouthLeft": "mouth_shift_l", "MouthRight": "mouth_shift_r", "CheekPuff": "cheek_puff", "TongueOut": "tongue_out",
}


#: The lids follow the gaze (the levator's tone is coupled to it): each eye's EyeLookUp also lifts
#: its upper lid (levator palpebrae) and EyeLookDown lowers it (the lid strip), by these shares of
#: the channel, fitted to the scanned eyeLook shapes on the settled poses of the rebuilt lids and the
#: stronger levator (docs/scan-face.md, "The skin under the chin set free": each the best of a sweep
#: by 0.05-0.1). The map binds the same shares; the channel takes the larger of the lid's own shape
#: and the gaze's share.
GAZE_LIDS = {"EyeLookUp": ("levator_palpebrae", 0.600), "EyeLookDown": ("orbicularis_oculi_lid", 0.700)}


def _rule(shape: str) -> Callable[[Getter], float] | None:
    """How one ARKit shape is computed from channel values (None: we cannot express it)."""
    s = _side(shape)
    base = shape.removesuffix("Left").removesuffix("Right")
    simple = SIMPLE_SHAPES
    span = SHAPE_SPAN.get(base, 1.0)
    if base in simple:
        name = simple[base] + s
        return lambda g: g(name) / span
    if base == "BrowDown":
        return lambda g: max(g("corrugator" + s), g("procerus")) / span
    if base == "MouthPress":  # the side's half of the lips' sphincter, or the whole (AU23/24) where larger
        return lambda g: max(g("orbicularis_oris" + s), g("orbicularis_oris")) / span
    if shape == "BrowInnerUp":
        return lambda g: 0.5 * (g("frontalis_inner_l") + g("frontalis_inner_r")) / span
    if shape == "JawOpen":
        return lambda g: g("jaw") / span
    if shape == "MouthShrugLower":
        return lambda g: g("mentalis") / span
    if shape == "JawLeft":
        return lambda g: max(0.0, g("jaw_sideways"))
    if shape == "JawRight":
        return lambda g: max(0.0, -g("jaw_sideways"))
    if shape == "MouthClose":  # the closure over its span, or the lips' lift, which follows the shape itself
        return lambda g: max(MOUTH_CLOSE_SPAN * g("lip_closure") / span, g(MOUTH_CLOSE_LIFT))
    if shape in ONE_CHANNEL:
        name = ONE_CHANNEL[shape]
        return lambda g: g(name) / span
    # gaze: +yaw looks towards the face's left: out for the left eye, in for the right one; each
    # eye's yaw is the shared one with the vergence (the left eye's minus it, the right one's plus)
    def left(g: Getter) -> float:
        return eye_yaws(g("eyes_yaw"), g("eyes_vergence"))[0]

    def right(g: Getter) -> float:
        return eye_yaws(g("eyes_yaw"), g("eyes_vergence"))[1]

    gaze = {
        "EyeLookOutLeft": lambda g: max(0.0, left(g)), "EyeLookInLeft": lambda g: max(0.0, -left(g)),
        "EyeLookInRight": lambda g: max(0.0, right(g)), "EyeLookOutRight": lambda g: max(0.0, -right(g)),
        "EyeLookUpLeft": lambda g: max(0.0, g("eyes_pitch")), "EyeLookUpRight": lambda g: max(0.0, g("eyes_pitch")),
        "EyeLookDownLeft": lambda g: max(0.0, -g("eyes_pitch")),
        "EyeLookDownRight": lambda g: max(0.0, -g("eyes_pitch")),
    }
    return gaze.get(shape)


RULES = {shape: _rule(shape) for shape in ARKIT_SHAPES}
UNSUPPORTED = tuple(s for s, r in RULES.items() if r is None)


def _drives(index: dict[str, int]) -> list[dict[int, float]]:
    """Each shape's channels (by place in `index`) as the import drives them: the channel's value
    per unit of the shape (its own channels at the shape's span, its `SHAPE_SHARES`, the gaze's
    lids)."""
    from puppet.capture.arkit_in import share_targets, shape_targets

    out: list[dict[int, float]] = []
    for shape in ARKIT_SHAPES:
        base = shape.removesuffix("Left").removesuffix("Right")
        own: dict[int, float] = {}
        for ch in shape_targets(shape):
            if ch in index:
                own[index[ch]] = max(own.get(index[ch], 0.0), SHAPE_SPAN.get(base, 1.0))
        for ch, share in SHAPE_SHARES.get(base, ()):
            for t in share_targets(shape, ch, index):
                if t in index:
                    own[index[t]] = max(own.get(index[t], 0.0), share)
        for look, (lid, share) in GAZE_LIDS.items():
            if base == look and lid + _side(shape) in index:
                own[index[lid + _side(shape)]] = share
        out.append(own)
    return out


#: Shapes the import drives from their weight alone (the gaze, the jaw's opening and sideways turn
#: and the inner brows' mean are written as they read).
_FIXED = tuple(s for s in ARKIT_SHAPES if s in ("BrowInnerUp", "JawOpen", "JawLeft", "JawRight") or s.startswith("EyeLook"))


class _Drives:
    """The import as a table: `k[s, c]` is how far shape s at full weight drives channel c (the
    channel takes the largest of its drives); `free` the shapes the export may choose."""

    def __init__(self, index: dict[str, int]) -> None:
        drives = _drives(index)
        self.k = np.zeros((len(ARKIT_SHAPES), max(index.values(), default=-1) + 1))
        for s, d in enumerate(drives):
            for c, v in d.items():
                self.k[s, c] = v
        self.free = np.array([s not in _FIXED for s in ARKIT_SHAPES])
        self.channels = np.flatnonzero(self.k.any(axis=0))
        self.close = ARKIT_SHAPES.index("MouthClose")


_TABLES: dict[tuple[str, ...], _Drives] = {}


def arkit_row(values: np.ndarray, index: dict[str, int]) -> list[float]:
    """The 52 blendshape weights (0..1) for one tick's channel values.

    Shapes share channels (pressed lips lift the chin, a sneer narrows the eye, the gaze lifts the
    lid; `SHAPE_SHARES`, `GAZE_LIDS`). A pose the shapes can give (any pose a stream of them
    gives) is written as each shape at the largest weight that drives none of its channels past the
    pose: streamed back, those weights give the pose itself, and exported again the same weights.
    Any other pose is written shape by shape from its own channel."""
    def g(name: str) -> float:
        i = index.get(name)
        return float(values[i]) if i is not None else 0.0

    row = [min(1.0, max(0.0, r(g))) if r is not None else 0.0 for r in RULES.values()]
    key = tuple(index)
    table = _TABLES.get(key)
    if table is None:
        table = _TABLES[key] = _Drives(index)
    k = table.k
    v = np.asarray(values, float)[: k.shape[1]]
    unit = np.array(row)
    unit[table.close] = min(1.0, unit[table.close] / MOUTH_CLOSE_SPAN)
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(k > 0.0, np.maximum(v, 0.0) / np.where(k > 0.0, k, 1.0), np.inf).min(axis=1)
    largest = np.where(table.free, np.clip(room, 0.0, 1.0), unit)
    lift = index.get(MOUTH_CLOSE_LIFT)
    if lift is not None:  # the lips' lift is mouthClose itself: the stream gave the shape that weight
        close = min(1.0, max(0.0, float(values[lift])))
        largest[table.close] = min(1.0, close / MOUTH_CLOSE_SPAN)
    given = (k * largest[:, None]).max(axis=0)
    if np.all(np.abs(given[table.channels] - v[table.channels]) <= 1e-9):
        largest[table.close] = close if lift is not None else largest[table.close] * MOUTH_CLOSE_SPAN
        return [float(w) for w in largest]
    return row


def timecode(frame: int, fps: float) -> str:
    """HH:MM:SS:FF.mmm with an integer frame count at `fps` (never seconds an importer rounds)."""
    ifps = max(1, round(fps))
    secs, ff = divmod(frame, ifps)
    hh, rem = divmod(secs, 3600)
    mm, ss = divmod(rem, 60)
    return f"{hh:02d}:{mm:02d}:{ss:02d}:{ff:02d}.000"


#: The gaze's full range (eyes_yaw, eyes_pitch = 1) as rotations in quarter turns: the renderer
#: turns the eyes 30 degrees sideways and 20 up or down.
EYE_YAW_TURN, EYE_PITCH_TURN = 30.0 / 90.0, 20.0 / 90.0


def rotation_row(values: np.ndarray, index: dict[str, int]) -> list[float]:
    """The nine rotation columns (quarter turns, as Live Link Face writes them) for one tick: the
    head's turn on the neck and both eyes' gaze (no eye roll)."""
    def g(name: str) -> float:
        i = index.get(name)
        return float(values[i]) if i is not None else 0.0

    (yaw_l, yaw_r), pitch = eye_yaws(g("eyes_yaw"), g("eyes_vergence")), g("eyes_pitch") * EYE_PITCH_TURN
    return [g("head_yaw"), g("head_pitch"), g("head_roll"), yaw_l * EYE_YAW_TURN, pitch, 0.0,
            yaw_r * EYE_YAW_TURN, pitch, 0.0]


class ArkitCsvWriter:
    """Writes Timecode, BlendShapeCount (61), the 52 shapes, then head and eye rotations."""

    def __init__(self, path: str | Path, channel_names: list[str], fps: float) -> None:
        self.index = {n: i for i, n in enumerate(channel_names)}
        self.fps = fps
        try:
            self._fh: IO[str] | None = open(path, "w", newline="", encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{path}: cannot write the ARKit CSV: {err.strerror}") from err
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["Timecode", "BlendShapeCount", *ARKIT_SHAPES, *ROTATIONS])

    def add(self, frame: int, values: np.ndarray) -> None:
        shapes = arkit_row(values, self.index)
        self._csv.writerow([timecode(frame, self.fps), len(ARKIT_SHAPES) + len(ROTATIONS),
                            *(f"{v:.6g}" for v in shapes), *(f"{v:.9g}" for v in rotation_row(values, self.index))])

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
