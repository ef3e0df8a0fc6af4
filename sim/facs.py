"""FACS action units and expression presets in terms of the face's channels.

AU -> muscles after the AU/muscle table in peers-facs-formats.md section D.2 (AU18 incisivus; AU22
both lips everted by the pars peripheralis, just parted; AU28 both lips rolled in; AU29 jaw thrust;
AU33 cheek blow, AU34 puff with the lips sealed; AU21 neck tightener, the platysma (its sheet over the
jowl and under the chin); AU19 tongue show, with the lips parted and the jaw
dropped a little, as it cannot show otherwise; AU30, the jaw sideways, is the signed channel
jaw_sideways, set directly, since a side's AU cannot lower a value); expressions after section D.1
(EMFACS-style combinations; sadness as 1+4+15+17 with the lids drooping (AU41, here a light AU43):
the scanned head's frontalis lifts the upper lids with the brows, which read as surprise without it;
anger as the glare 4+5+7+23, the lids tightened, not shut); AU7 (lid tightener) raises the lower lid
by its own channel, the lower lid's palpebral orbicularis, with a share of the lid channel lowering
the upper lid; AU5 (upper lid raiser) is the levator
palpebrae, a lid muscle rather than a skin one, given its own channel. Fear has it (1+2+4+5+20+26);
surprise leaves out the slight 5B FACS gives it, because this face's 1+2 already lifts the upper lid
margin 8-10 mm with the brows. A side suffix restricts a bilateral AU to one side of the face:
"AU12_L" (the face's own left) or "AU12_R"; AU17, AU23 and AU24 are one channel for both sides
(the mentalis, the lips' sphincter), and their one-sided forms drive that side's half
(`sim.channels.HALVES`).

Combination rule: applying an AU sets each of its channels to max(current, weight * intensity), so
presets and AUs that share a muscle do not add up beyond what either asks for.
"""

from __future__ import annotations

from sim.channels import ChannelError, channel_spec, check_value, unknown_name
from sim.state import FaceControl


def _both(base: str, w: float = 1.0) -> dict[str, float]:
    return {f"{base}_l": w, f"{base}_r": w}


_BASE: dict[str, dict[str, float]] = {
    "AU1": _both("frontalis_inner"),
    "AU2": _both("frontalis_outer"),
    "AU4": {**_both("corrugator"), "procerus": 0.8},
    "AU5": _both("levator_palpebrae"),
    "AU6": _both("orbicularis_oculi"),
    "AU7": {**_both("orbicularis_oculi_lid", 0.45), **_both("orbicularis_oculi_lower_lid")},
    "AU9": {**_both("levator_labii_alaeque_nasi"), **_both("levator_labii", 0.3)},
    "AU10": _both("levator_labii"),
    "AU11": _both("zygomaticus_minor"),
    "AU12": _both("zygomaticus_major"),
    "AU13": _both("levator_anguli_oris"),
    "AU14": _both("buccinator"),
    "AU15": _both("depressor_anguli_oris"),
    "AU16": _both("depressor_labii"),
    "AU17": {"mentalis": 1.0},
    "AU20": _both("risorius"),
    "AU21": _both("platysma"),
    "AU23": {"orbicularis_oris": 0.7},
    "AU24": {"orbicularis_oris": 1.0},
    "AU25": {**_both("depressor_labii", 0.4), "jaw": 0.1},
    "AU26": {"jaw": 0.5},
    "AU27": {"jaw": 1.0},
    "AU18": {"incisivus": 1.0},
    "AU19": {"tongue_out": 1.0, "jaw": 0.35, **_both("depressor_labii", 0.4)},
    "AU22": {"orbicularis_oris_peripheralis_upper": 1.0, "orbicularis_oris_peripheralis_lower": 1.0,
             "jaw": 0.05},
    "AU28": {"orbicularis_oris_marginalis_upper": 1.0, "orbicularis_oris_marginalis_lower": 1.0},
    "AU29": {"jaw_forward": 1.0},
    "AU33": {"cheek_puff": 0.6},
    "AU34": {"cheek_puff": 1.0, "orbicularis_oris": 0.3},
    "AU43": _both("orbicularis_oculi_lid"),
    "AU45": _both("orbicularis_oculi_lid"),
}


def _sided(table: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    out = dict(table)
    for au, chans in table.items():
        for suffix, keep in (("_L", "_l"), ("_R", "_r")):
            side = {c: w for c, w in chans.items() if c.endswith(keep)}
            if au in HALF_AUS:  # the unsided muscle's half on that side (sim.channels.HALVES)
                side = {c + keep: w for c, w in chans.items()}
            if side:
                out[au + suffix] = side
    return out


#: AUs of one unsided paired muscle whose one-sided form ("AU24_L") drives that side's half.
HALF_AUS = ("AU17", "AU23", "AU24")


AU_TABLE: dict[str, dict[str, float]] = _sided(_BASE)
"""AU name ("AU12", or one-sided "AU12_L" / "AU12_R") -> {channel: weight}."""

EXPRESSIONS: dict[str, dict[str, float]] = {
    "happiness": {"AU6": 0.6, "AU12": 1.0},
    "sadness": {"AU1": 1.0, "AU4": 0.1, "AU15": 1.0, "AU17": 0.5, "AU43": 0.2},
    "surprise": {"AU1": 1.0, "AU2": 1.0, "AU26": 0.8},
    "fear": {"AU1": 1.0, "AU2": 0.15, "AU4": 0.6, "AU5": 0.8, "AU20": 1.0, "AU26": 0.5},
    "anger": {"AU4": 1.0, "AU5": 0.3, "AU7": 0.6, "AU23": 1.0},
    "disgust": {"AU9": 0.85, "AU10": 0.85, "AU4": 0.4, "AU17": 0.4},
    "contempt": {"AU12_R": 0.6, "AU14_R": 0.6},
}
"""Expression name -> {AU: intensity 0..1}. Contempt is one-sided (the face's right)."""

FACE_EXPRESSIONS: dict[str, dict[str, dict[str, float]]] = {
    "ict": {
        "happiness": {"AU6": 0.3, "AU10": 0.4, "AU12": 1.0, "AU13": 1.0, "AU25": 0.8},
        "sadness": {"AU1": 1.0, "AU4": 0.42, "AU11": 0.6, "AU15": 1.0, "AU17": 1.0, "AU43": 0.35},
        "surprise": {"AU1": 0.8, "AU2": 0.8, "AU5": 0.7, "AU26": 1.0},
        "fear": {"AU1": 1.0, "AU2": 0.1, "AU4": 0.6, "AU5": 1.0, "AU20": 1.0, "AU25": 0.5, "AU26": 0.3},
        "anger": {"AU2": 0.15, "AU4": 1.0, "AU5": 0.9, "AU7": 0.6, "AU10": 0.3, "AU17": 0.7, "AU23": 1.0},
        "disgust": {"AU9": 1.0, "AU10": 0.4, "AU4": 0.9, "AU15": 1.0, "AU25": 0.6},
    },
}
"""Per face (its rig's name: "ict" is the scanned head and its identities), the presets whose
intensities differ from EXPRESSIONS: the same FACS combinations pushed harder where the face's own
actions are weaker. The scanned head's stiffer skin moves less under the same channel values; at
the shared intensities the emotion observer (`benchmarks/observer.py`) read its smile and sadness
as neutral and its fear as surprise. Fear with the brows fully drawn down (AU4 1.0), disgust at
full AU9+10 and sadness with the lids drooping further (AU43 0.7) over a stronger AU4 read on the
scan (its inner brows still rising 1.3 mm); on the skin fitted to the scans (`FaceRig.skin`, laxer)
disgust at full AU9+10 folded the nose (0.21 cm2) and read as anger (0.83): at 0.55 it folds nothing
and reads as disgust (0.34; 0.7 read angry 0.37). On the procedural face they overshoot its
amplitude targets (fear's brows drawn together 6.7 mm, limit 5; the nose wing raised 10.6 mm,
limit 10; sadness' inner brows rising 2.1 mm at AU4 0.4 and resolution 1, target 3), so they are the scan's own.
Happiness on the scan is the broad smile: the corners drawn up and out (AU12) and up (AU13), the
upper lip raised a little over the parted lips (AU10 0.3, AU25) and the cheeks raised a little
(AU6 0.3). With the lids rebuilt as the scan's blink (`sim.face.scan.lids`) the orbicularis oculi
at full narrowed the eyes and the observer read AU6+12+25 as neutral (happy 0.11); this reads
happy 0.59 (AU6 0.5: 0.49, AU6 0: 0.78).
Fear is 1+2+4+5+20+25+26 with the outer brows raised only a little (AU2 0.15; at 0.3 fear 0.39 with
surprise 0.31, at 0.45-0.6 surprise); it read sad (sad 0.50, fear 0.15) until the levator was made
stronger (`sim.face.scan.rig.FORCE_OF`: under the brows drawn down it lifted the lid 3.0 mm, now
3.8, target 6.5+), and reads fear 0.63 (AU26 0.4: 0.43; AU2 0.1 or 0.2: 0.35-0.48). Anger is the
glare 4+5+7+23 with the lids raised harder (AU5 0.5): angry 0.47 (AU5 0.3, 0.4: 0.49, 0.41; AU7
0.45 instead of 0.6: 0.20-0.51, read neutral at AU5 0.4). Disgust is 9+10 with the brows lowered and the
lips parted (AU4 0.6, AU25; no AU17): disgust 0.78 (anger 0.15), where AU17 0.5 read disgust 0.44
with anger 0.35 close; AU4 0.5: 0.67, AU9+10 0.5 or 0.6: 0.66-0.71, AU17 0.3 added: 0.64.
Read again on the softened, bound forehead (`observer.py --faces ict --views`, the frontal camera
and eight others up to 12 degrees off, docs/scan-face.md "The presets on the scanned head"):
surprise is FACS 1+2+5+26 with the upper lids raised (AU5 0.6; the retaining ligament holds the
scan's lids under raised brows, so 1+2 alone left the iris under the lid and read neutral as often
as surprise, 0.45 against 0.42) and the jaw dropped further (AU26 1.0): surprise 0.90, 0.82-0.99 over
the views (AU5 0.5-0.7 alike); sadness is 1+4+15+17 without the outer brows (AU2 0.25 gave the
brows an arch that read neutral from above): 0.89, was 0.75; anger tightens the lids harder (AU7
0.8; 0.6 read angry 0.33 against sad 0.31): 0.51 (AU7 0.9, AU5 0.4: 0.38, 0.50).
Then, for the nine views: anger is FACS 4+5+7+17+23 (the chin raised, AU17 1.0; lids at AU7 0.85)
with the outer brows lifted a little (AU2 0.3: the scan's AU4 draws the whole brow down, its tail
drooping as in sadness; Waters' anger pulls the outer frontalis too): angry 0.62 and angry in 7 of
the nine views (5 before; it read sad from below); AU2 0.25: 6 views, 0.32-0.35 reads neutral
(the brows flatten), without AU2 5 views. Sadness deepens the nasolabial furrow harder (AU11 0.6,
EMFACS 1+4+11+15): 0.92 and 8 views (AU11 0.4-0.7: 7-8). Disgust pulls the lip corners down
(AU15 0.4, the 9+15+16 of the EMFACS table): 0.74 and 8 views (AU15 0.3-0.5: 0.69-0.71, 8 views).
Anger still read sad from two views below until AU7 raised the lower lid (its own channel; before,
AU7 was the lid channel alone, which lowers the scan's upper lid as its blink does, and lids lowered
under lowered brows read sad from below): the same mix reads angry from all nine views (0.47-0.78).
Retuned on the rig with the skin's tether anchors and the hanging lashes (frontal: fear read as
surprise, anger as neutral, disgust as anger, 4 of 7): disgust AU9+10 0.7 with AU4 0.75 and AU15 0.3
(disgust 0.85; 8 of 9 views over AU4 0.7-0.9 and AU15 0.3-0.4), fear and anger with the outer brows
raised less (AU2 0.1: fear 0.63; AU2 0.15: angry 0.71): 7 of 7, mean 0.83 (docs/scan-face.md,
"Retuned on the anchored rig"). Sadness's lids then droop less (AU43 0.7 -> 0.35): at 0.7 the
eyes were nearly shut where the scan's sadness keeps them open under heavy lids; at 0.35 the iris
shows as in the scan and it reads sad 0.94 (0.95 at 0.7), 8 of 9 views (0.3-0.45: 0.86-0.91, 8 of 9).
Looked at beside the scan's own shapes (docs/scan-face.md, "The gallery's weak points fixed"):
surprise raises the brows by less (AU1 and AU2 0.8) with the lids raised more (AU5 0.7), which
leaves the forehead even where AU1+2 at full pushed two lumps up over the brows; anger glares
with the lids raised fully (AU5 1.0) and tightened less (AU7 0.8), the irises showing under the
lowered brows where AU7 0.85 over AU5 0.5 all but shut the eyes under the lashes. With the
corrugator's anchors refitted over a zone grown 1.5 cm (its pull carries the brow's tail and the
temple as the scan's browDown does, docs/scan-face.md "The brows carried whole"), disgust's brows
at AU4 0.75 came down far enough to read angry (disgust 0.55, angry 0.31): at AU4 0.6 disgust
0.77 (0.5: 0.65); and fear's brows drawn fully down against its inner brows raised turned 0.26 cm2
of the glabella's skin over (limit 0.1): at AU4 0.7 0.07 cm2, fear 0.60 (0.8: 0.11 cm2, 0.60; at
1.0 it read fear 0.79); and anger's brows, lower, left 18.7 % of the left iris showing (the glare's
test asks a fifth): its lids raised harder, AU5 0.7, show more and read angry 0.56 (AU5 0.6: 0.57,
0.8: 0.47; AU4 0.85 with AU5 0.6: 18.9 %, angry 0.34).
Retuned when the nose wing's slip of AU9's muscle and the upper lip's elevators refitted over grown
zones came (docs/scan-face.md, "The nose wing's slip and the upper lip's elevators"): at the preset
before (AU9+10 0.7, AU4 0.75) the lip rose higher and read angry 0.38 (disgust 0.36); disgust lifts
the nose harder than the lip (AU9 0.9, AU10 0.7) under brows drawn down harder (AU4 0.9): disgust
0.90 and in all nine views (0.73-0.90), where AU9+10 0.8 with AU4 0.85-0.9 read 0.87-0.88 frontally
and missed one view, AU9+10 1.0 read angry.
Retuned when the jaw's hinge was fitted to the scan's jawOpen (`sim.face.scan.jaw_fit`; the parted
lips' small opening, AU25's jaw 0.1, now carries the chin back 2 mm as the scan's opening does, and
the lips' skin follows the mandible closer): at AU25 1.0 happiness read happy 0.40 (surprise and
neutral 0.24) and disgust 0.78 (angry 0.20); with the lips parted less, happiness at AU25 0.8 reads
0.75 (0.3 / 0.45 / 0.6: 0.72 / 0.69 / 0.71) and disgust at AU25 0.6 0.94 (0.8: 0.78).
Retuned when the lid channel's tissue was fitted with the closed lids held meeting (docs/scan-face.md,
"The blink's lid fold held"): AU7's share of the lid channel narrows the glare from above, and
anger at AU5 0.7 / AU7 0.8 read angry 0.41 with the eyes all but shut; its lids raised harder and
tightened less, AU5 0.9 / AU7 0.6, read 0.50 and angry in 7 of the nine views (AU7 0.4: 0.42, 7 of 9;
AU7 0.5: 0.36, 7; AU2 0.3: 0.49, 7; AU7 0.9: 0.54 frontally, but a sixth of the iris shows).
Retuned when the upper lip's elevators came to push the infraorbital triangle out and their fields were
refitted on it (docs/scan-face.md, "The infraorbital triangle's bulge"): at AU9 0.9 / AU10 0.7 disgust
still read 0.84, but the lip under the nose rose over the wings' rims (each nostril 1.7-2.0 mm lower
from the front, 1.0-1.4 before) and 0.063 cm2 of skin beside the wings turned over; the nose lifted
at full and the lip less, AU9 1.0 / AU10 0.5, reads 0.85 with nothing turned over and the nostrils
0.7-1.0 mm lower (AU10 0.6: 0.82, 1.2-1.4 mm).
Retuned when the corrugator's field was refitted over a zone grown 4.5 cm (docs/scan-face.md, "The
temple carried with the brows"): fear's brows drawn together at AU4 0.7 turned 0.108 cm2 of the
glabella's skin over (limit 0.1); at AU4 0.6 0.067 cm2 and fear 0.76 (the observer 7 of 7, mean 0.79).
Retuned when the corrugator's field over the temple and the infraorbital triangle's bulge came together
(the merged rig): disgust at AU15 0.3 read angry (0.21; angry 0.72: the brows' V and the creases from
the nose's wings); the corners pulled down harder, AU15 1.0, read disgusted 0.94 and in 9 of the nine
views (0.51-0.97; AU15 0.8: 0.91 and 7 of 9; AU4 0.7, 0.5, 0.3 or 0 at AU15 0.3: angry). On the same rig the mentalis' pout (its
two bellies pushing the lower lip out) made anger's AU17 1.0 a pout: anger read 0.42 and sad from three
of the nine views; the upper lip raised a little, AU10 0.3 (anger's prototype 4+5+7+10+23), with AU17
0.7 reads 0.67 and angry in 9 of 9 (AU10 0.3 alone: 0.60, 8 of 9; AU10 0.45: disgust from three views;
AU17 0.6 or 0.3, AU7 0.8, AU2 0.3: 6-7 of 9). Then the depressors' and the upper lip's elevators'
fields refitted with a smaller ridge (docs/scan-face.md, "The depressors' and the elevators' fields
carried further"): the lifters reach further, so disgust AU10 0.5 read angry (0.24) and AU10 0.4 reads
0.68 (8 of 9 views; AU9 0.7: 0.85 but 6 of 9; AU10 0.3: 0.81, 7 of 9); fear's lips parted by AU25 1.0
read 0.55 (its depressor_labii share pulls the lower lip further), AU25 0.5 reads 0.83 and fear in 9 of
9 (0.7: 0.81, 8 of 9); happiness AU10 0.3 read 0.69, 0.4 reads 0.83 (0.15: 0.62; 0: neutral)."""


FACE_EXPRESSIONS["imported"] = {
    "fear": {"AU1": 1.0, "AU4": 1.0, "AU5": 1.0, "AU20": 1.0},
}
"""An imported head (`sim.face.transfer`) has no teeth, so a dropped jaw opens a dark hole that the
emotion observer read as surprise (and AU2's arched brows with it): its fear is the brows raised
at the inner end and drawn together, the lids raised and the lips stretched, with the jaw shut
(on the development heads of `benchmarks/observer_mesh.py`: fear read as fear, 0.89 and 0.87,
where the shared preset read MakeHuman's as surprise, fear 0.09). Rigs imported before this
table ask for no presets and keep the shared ones."""

FACE_EXPRESSIONS["imported-2"] = {
    **FACE_EXPRESSIONS["imported"],  # the sadness: the scanned head's as it was then (with AU2 0.25)
    "sadness": {"AU1": 1.0, "AU2": 0.25, "AU4": 0.42, "AU11": 0.3, "AU15": 1.0, "AU17": 1.0, "AU43": 0.7},
}
"""Heads imported since the renderer draws their teeth and `--rest-lips` can bring their lips
together: the fear above, and the scanned head's sadness (the brows drawn down harder over the
raised inner ends, the lids drooping further, the chin raised, AU11): on the development heads of
`benchmarks/observer_mesh.py` the shared sadness read as fear on MakeHuman (sad 0.48, fear 0.50)
and on its face mask (0.43, 0.56), this one as sad (0.45, 0.73; Nefertiti's 0.39, was 0.43). Rigs
imported with "imported" keep that table (and their takes' bits)."""


FACE_EXPRESSIONS["imported-3"] = {
    **FACE_EXPRESSIONS["imported-2"],
    "sadness": {au: v for au, v in FACE_EXPRESSIONS["imported-2"]["sadness"].items() if au != "AU2"},
}
"""Heads imported since the transfer makes the frontalis cover the whole brow and matches each
channel's force to the reference's (`puppet import-face`; their brows rise as far as the built-in
face's): the sadness above without the outer brows raised (AU2 0.25, the scanned head's own
tuning; FACS sadness is 1+4+15). With the brows now rising in full, the outer brows raised with
the inner read as fear on the development heads of `benchmarks/observer_mesh.py` often enough to
lose one (sad 0.83, 0.69, 0.33 on MakeHuman, its face mask and Nefertiti, Nefertiti read neutral);
without AU2 0.55, 0.77, 0.46, all three read sad. The shared sadness (AU1 over a light AU4, AU43
0.2) read as fear on MakeHuman and its mask (0.94, 0.90). Rigs imported with "imported-2" keep
that table (and their takes' bits)."""

def preset_face(rig: object) -> str | None:
    """The key of `expressions_for` for a rig: its `presets` when it names them, else its name."""
    return getattr(rig, "presets", "") or getattr(rig, "name", None)


def expressions_for(face: str | None = None) -> dict[str, dict[str, float]]:
    """The presets of one face (its rig's name; None or an unknown name: EXPRESSIONS)."""
    return {**EXPRESSIONS, **FACE_EXPRESSIONS.get(face or "", {})}


def _normalise_au(au: str) -> str:
    key = au.strip().upper()
    if not key.startswith("AU"):
        key = "AU" + key
    return key


def apply_au(control: FaceControl, au: str, intensity: float) -> None:
    """Raise the channels of one AU to weight * intensity (intensity 0..1); ChannelError for an
    unknown AU or an out-of-range intensity."""
    key = _normalise_au(au)
    if key not in AU_TABLE:
        raise ChannelError(unknown_name("action unit", au, AU_TABLE))
    v = float(intensity)
    if not (0.0 <= v <= 1.0):
        raise ChannelError(f"action unit {key} takes intensities in 0..1, got {intensity!r}")
    for channel, weight in AU_TABLE[key].items():
        spec = channel_spec(channel)
        target = check_value(spec, min(spec.hi, weight * v))
        control.set(channel, max(control.get(channel), target))


def apply_expression(control: FaceControl, name: str, weight: float = 1.0, face: str | None = None) -> None:
    """Apply a preset's AUs scaled by weight (0..1), at the intensities of `face` (its rig's name,
    `expressions_for`); ChannelError for an unknown name or weight."""
    key = name.strip().lower()
    table = expressions_for(face)
    if key not in table:
        raise ChannelError(unknown_name("expression", name, EXPRESSIONS))
    w = float(weight)
    if not (0.0 <= w <= 1.0):
        raise ChannelError(f"expression {key} takes weights in 0..1, got {weight!r}")
    for au, intensity in table[key].items():
        apply_au(control, au, intensity * w)
