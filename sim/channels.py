"""The face's control channels: one per muscle (activation 0..1), the jaw, the eyes, age and the
head's turn on the neck.

The list is static so that a channel's index never depends on which rig is loaded: a recording made
on one rig replays on another; new channels are added at the end. Each muscle channel names the muscle model it uses (seed 000 section 3)
and the FACS action units it takes part in (see `sim.facs`).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass


class ChannelError(ValueError):
    """An unknown channel, AU or expression name, or a value outside a channel's range. The message
    names the valid choices, so it can be shown to a user as one line."""


@dataclass(frozen=True)
class ChannelSpec:
    """One input of the face. kind: "muscle" | "jaw" | "eyes" | "age" | "head" | "tongue"; lo..hi is the
    valid range and default the value at rest; muscle_type: "linear" | "sphincter" | "sheet" | "patch"
    (a force over a region of skin, sim.muscles.patch_force) | "pressure" (a patch pushing along the
    skin's normal) for muscle channels (activation 0..1), else None."""

    name: str
    kind: str
    aus: tuple[str, ...]
    lo: float
    hi: float
    default: float
    muscle_type: str | None
    doc: str


def _muscle(name: str, muscle_type: str, aus: tuple[str, ...], doc: str) -> ChannelSpec:
    return ChannelSpec(name, "muscle", aus, 0.0, 1.0, 0.0, muscle_type, doc)


def _pair(base: str, muscle_type: str, aus: tuple[str, ...], doc: str) -> tuple[ChannelSpec, ...]:
    return (
        _muscle(f"{base}_l", muscle_type, aus, doc + " (face's left)"),
        _muscle(f"{base}_r", muscle_type, aus, doc + " (face's right)"),
    )


CHANNEL_SPECS: tuple[ChannelSpec, ...] = (
    *_pair("frontalis_inner", "sheet", ("AU1",), "inner brow raiser, frontalis pars medialis"),
    *_pair("frontalis_outer", "sheet", ("AU2",), "outer brow raiser, frontalis pars lateralis"),
    *_pair("corrugator", "linear", ("AU4",), "brow lowerer, draws the brows down and together"),
    _muscle("procerus", "linear", ("AU4",), "brow lowerer, pulls the skin between the brows down"),
    *_pair("orbicularis_oculi", "sphincter", ("AU6",), "cheek raiser, orbicularis oculi pars orbitalis"),
    *_pair(
        "orbicularis_oculi_lid",
        "sheet",
        ("AU7", "AU43", "AU45"),
        "lid tightener / blink, orbicularis oculi pars palpebralis (two sheets, one per lid); 1 closes the lids",
    ),
    *_pair(
        "levator_palpebrae",
        "sheet",
        ("AU5",),
        "upper lid raiser, levator palpebrae superioris: lifts the upper lid into the orbit (wide eyes)",
    ),
    *_pair(
        "levator_labii_alaeque_nasi",
        "linear",
        ("AU9",),
        "nose wrinkler, raises the nose wings and the upper lip",
    ),
    *_pair("levator_labii", "linear", ("AU10",), "upper lip raiser"),
    *_pair("zygomaticus_minor", "linear", ("AU11",), "nasolabial deepener"),
    *_pair("zygomaticus_major", "linear", ("AU12",), "lip corner puller (smile)"),
    *_pair("levator_anguli_oris", "linear", ("AU13",), "sharp lip puller, raises the mouth corner"),
    *_pair("buccinator", "linear", ("AU14",), "dimpler, draws the mouth corner back"),
    *_pair("depressor_anguli_oris", "linear", ("AU15",), "lip corner depressor"),
    *_pair("depressor_labii", "linear", ("AU16",), "lower lip depressor"),
    _muscle("mentalis", "sheet", ("AU17",), "chin raiser, pushes the chin boss and lower lip up"),
    *_pair("risorius", "linear", ("AU20",), "lip stretcher, pulls the mouth corner sideways"),
    _muscle(
        "orbicularis_oris", "sphincter", ("AU23", "AU24"), "lip tightener / pressor, around the mouth"
    ),
    ChannelSpec(
        "jaw", "jaw", ("AU26", "AU27"), 0.0, 1.0, 0.0, None, "jaw opening, 0 closed .. 1 fully open"
    ),
    ChannelSpec(
        "eyes_yaw", "eyes", (), -1.0, 1.0, 0.0, None, "gaze left/right, + = towards the face's left"
    ),
    ChannelSpec("eyes_pitch", "eyes", (), -1.0, 1.0, 0.0, None, "gaze up/down, + = up"),
    ChannelSpec("age", "age", (), 0.0, 120.0, 30.0, None, "age in years; drives the wrinkles"),
    ChannelSpec("head_yaw", "head", ("AU51", "AU52"), -1.0, 1.0, 0.0, None,
                "head turn left/right on the neck, + = towards the face's left; 1 = a quarter turn (90 degrees)"),
    ChannelSpec("head_pitch", "head", ("AU53", "AU54"), -1.0, 1.0, 0.0, None,
                "head tilt up/down on the neck, + = chin up; 1 = a quarter turn"),
    ChannelSpec("head_roll", "head", ("AU55", "AU56"), -1.0, 1.0, 0.0, None,
                "head tilt sideways, + = the top of the head towards the face's left shoulder; 1 = a quarter turn"),
    _muscle("incisivus", "linear", ("AU18",),
            "lip pucker, incisivus labii superioris and inferioris: draw the mouth corners towards the midline "
            "so the lips bunch and push forward"),
    _muscle("orbicularis_oris_peripheralis_upper", "patch", ("AU22",),
            "upper lip everted and pushed forward, orbicularis oris pars peripheralis (funneler with the lower "
            "part; alone: the upper lip's shrug)"),
    _muscle("orbicularis_oris_peripheralis_lower", "patch", ("AU22",),
            "lower lip everted and pushed forward, orbicularis oris pars peripheralis (funneler with the upper part)"),
    _muscle("orbicularis_oris_marginalis_upper", "patch", ("AU28",),
            "upper lip rolled in over the teeth, orbicularis oris pars marginalis (lip suck)"),
    _muscle("orbicularis_oris_marginalis_lower", "patch", ("AU28",),
            "lower lip rolled in over the teeth, orbicularis oris pars marginalis (lip suck)"),
    _muscle("lip_closure", "patch", ("AU24",),
            "lips meeting over an open jaw: the marginal orbicularis oris draws the upper lip down and the "
            "lower lip up"),
    *_pair("mouth_shift", "patch", (),
           "both lips drawn sideways as one band, the buccinator and risorius of that side pulling the "
           "orbicularis ring through the modiolus"),
    _muscle("cheek_puff", "pressure", ("AU33", "AU34"),
            "cheek puff: air held in the mouth at a pressure, pushing the cheeks out along the skin's normal"),
    ChannelSpec("jaw_forward", "jaw", ("AU29",), 0.0, 1.0, 0.0, None,
                "jaw thrust: the mandible slides forward (1 = ~8 mm, the adult maximum)"),
    ChannelSpec("jaw_sideways", "jaw", ("AU30",), -1.0, 1.0, 0.0, None,
                "jaw sideways, + = towards the face's left: the mandible turns about one condyle and shifts "
                "(1 = ~9 mm at the chin)"),
    ChannelSpec("tongue_out", "tongue", ("AU19",), 0.0, 1.0, 0.0, None,
                "tongue show: the tongue pushed out between the lips; moves a face's tongue where it has one "
                "(the scanned head), no skin on the procedural face"),
    ChannelSpec("eyes_vergence", "eyes", (), -1.0, 1.0, 0.0, None,
                "the eyes turned towards each other (+, looking near) or apart (-): each eye turns by it on "
                "top of eyes_yaw, the left one towards the face's right; 1 = 30 degrees each"),
    *_pair("orbicularis_oculi_lower_lid", "patch", ("AU7",),
           "lower lid tightener, orbicularis oculi pars palpebralis of the lower lid: its fibres, curved "
           "under the eye from canthus to canthus, straighten as they tighten and raise the lower lid"),
    *_pair("orbicularis_oris", "sphincter", ("AU23", "AU24"),
           "one side's half of the lips' sphincter (the lips pressed on that side, ARKit's mouthPress): the "
           "whole channel's field weighted smoothly across the midline"),
    *_pair("mentalis", "sheet", ("AU17",),
           "one side's half of the chin raiser (the chin's soft tissue pushed up on that side): the whole "
           "channel's field weighted smoothly across the midline"),
    _muscle("lip_lift", "patch", (),
            "the closed lips lifted and carried forward as one, as they are when they meet over an open jaw "
            "(ARKit's mouthClose): the lower lip's elevators push it up against the upper lip, which rides up "
            "on it, and forward"),
    *_pair("platysma", "patch", ("AU21",),
           "neck tightener, platysma: the thin sheet from the lower face's skin (the mandible's border, the "
           "corner's depressors, the jowl) down over the neck draws the jowl out and down and the skin under "
           "the chin down towards the chest"),
)

CHANNEL_NAMES: tuple[str, ...] = tuple(spec.name for spec in CHANNEL_SPECS)
CHANNEL_INDEX: dict[str, int] = {name: i for i, name in enumerate(CHANNEL_NAMES)}
MUSCLE_CHANNELS: tuple[str, ...] = tuple(s.name for s in CHANNEL_SPECS if s.kind == "muscle")

#: Sided halves of unsided paired muscles: half -> (whole channel, side). A half's pull is its whole
#: channel's field weighted by the side's share across the midline (`sim.build.side_weight`), so the
#: two halves at one value pull as the whole does; the whole stays for the unsided uses (the FACS
#: table's AU17/AU23/AU24, the presets, takes recorded before the halves).
HALVES: dict[str, tuple[str, str]] = {
    f"{whole}_{side}": (whole, side) for whole in ("orbicularis_oris", "mentalis") for side in ("l", "r")
}


def unknown_name(kind: str, name: object, valid: Iterable[str]) -> str:
    """One short line for an unknown `kind` of name: every valid name when they fit in a short
    line, else the nearest ones and where the whole list is (`puppet channels`)."""
    valid = list(valid)
    said = repr(str(name)[:60] + ("..." if len(str(name)) > 60 else ""))
    every = ", ".join(valid)
    if len(every) <= 200:
        return f"unknown {kind} {said}; valid: {every}"
    near = difflib.get_close_matches(str(name)[:60], valid, n=4, cutoff=0.5)
    hint = f"nearest: {', '.join(near)}; " if near else ""
    return f"unknown {kind} {said}; {hint}`puppet channels` lists every one"


def channel_spec(name: str) -> ChannelSpec:
    """The spec of a channel, or ChannelError naming the nearest valid names."""
    try:
        return CHANNEL_SPECS[CHANNEL_INDEX[name]]
    except KeyError:
        raise ChannelError(unknown_name("channel", name, CHANNEL_NAMES)) from None


def check_value(spec: ChannelSpec, value: float) -> float:
    """value as float if it lies in the channel's range, else ChannelError naming the range."""
    v = float(value)
    if not (spec.lo <= v <= spec.hi):  # also rejects NaN
        raise ChannelError(f"channel {spec.name!r} takes values in {spec.lo:g}..{spec.hi:g}, got {value!r}")
    return v
