"""Face-tracking streams as devices: Face Cap and VMC (OSC), iFacialMocap (UDP text) and Live Link
Face (binary UDP). Whatever the wire says, the controls are the 52 ARKit blendshapes under
Apple's names (``eyeBlinkLeft`` ... ``tongueOut``), absolute axes in 0..1, and the head's and eyes'
rotations (``headYaw`` ... ``rightEyeRoll``), absolute axes in -1..1 where 1 is a quarter turn
(90 degrees), as Live Link Face sends them: so one map drives the face from any of them
(``puppet/maps/arkit.toml``). Each stream has a pure parser (bytes and a time in, events out) and a
thin UDP device (``devices.udp``: localhost by default).

Rotation signs (the face's own frame): yaw + turns towards the face's left, pitch + tilts the
chin up, roll + tips the top of the head towards the face's left shoulder.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping
from typing import Any, ClassVar

from devices.base import ControlInfo
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from devices.udp import UdpListenerDevice
from devices.warn import WarningCounter

#: Apple's ARKit blendshape names, in the column order of Live Link Face's CSV recordings (which
#: lists JawRight before JawLeft and MouthRight before MouthLeft: its binary packet does not, see
#: devices.facestream.livelink.WIRE_ORDER).
ARKIT_NAMES = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawRight", "jawLeft", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthRight", "mouthLeft", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
)
#: The head's and eyes' rotations a tracker sends besides the blendshapes (-1..1, 1 = 90 degrees).
ROTATION_NAMES = ("headYaw", "headPitch", "headRoll", "leftEyeYaw", "leftEyePitch", "leftEyeRoll",
                  "rightEyeYaw", "rightEyePitch", "rightEyeRoll")
#: Rotations whose sign flips when left and right are swapped (a mirror turns yaw and roll around).
FLIP_ON_MIRROR = frozenset(n for n in ROTATION_NAMES if n.endswith(("Yaw", "Roll")))
#: One quarter turn: a rotation of this many degrees is 1.0.
QUARTER_TURN = 90.0
_BY_KEY = {n.lower(): n for n in (*ARKIT_NAMES, *ROTATION_NAMES)}


def _swap_sides(n: str) -> str:
    n = n.replace("Left", "\0").replace("Right", "Left").replace("\0", "Right")
    return n.replace("left", "\0").replace("right", "left").replace("\0", "right")


#: Each name with Left and Right swapped (for senders that report the image's side).
MIRRORED = {n: _swap_sides(n) for n in (*ARKIT_NAMES, *ROTATION_NAMES)}


@functools.lru_cache(maxsize=1024)
def arkit_name(name: str) -> str | None:
    """The ARKit name for a sender's spelling: any case (``EyeBlinkLeft``), ``_L``/``_R``
    suffixes (``eyeBlink_L``, iFacialMocap) or ``Left``/``Right``; None when it is none of them."""
    key = name.strip().lower()
    if key.endswith("_l"):
        key = key[:-2] + "left"
    elif key.endswith("_r"):
        key = key[:-2] + "right"
    return _BY_KEY.get(key)


def arkit_controls() -> list[ControlInfo]:
    """The 52 blendshapes as absolute axes 0..1, then the nine rotations as axes -1..1."""
    return ([ControlInfo(n, "axis", 0.0, 1.0) for n in ARKIT_NAMES]
            + [ControlInfo(n, "axis", -1.0, 1.0) for n in ROTATION_NAMES])


def degrees_to_turn(deg: float) -> float:
    """A rotation in degrees as the streams' -1..1 (90 degrees = 1)."""
    return deg / QUARTER_TURN


def arkit_euler(prefix: str, x: float, y: float, z: float) -> dict[str, float]:
    """Rotation controls from Euler angles in degrees about ARKit's face axes (+x the face's left,
    +y up, +z out of the face, right-handed: +x turns the nose down, +z the crown to the face's
    right), as Face Cap and iFacialMocap send them; ``prefix`` is ``head``, ``leftEye`` or
    ``rightEye``."""
    return {prefix + "Yaw": degrees_to_turn(y), prefix + "Pitch": degrees_to_turn(-x),
            prefix + "Roll": degrees_to_turn(-z)}


def unity_head(qx: float, qy: float, qz: float, qw: float) -> dict[str, float]:
    """Head rotation controls from a bone quaternion in Unity's left-handed frame (x right, y up,
    z forward, as VMC sends bones), the avatar facing +z."""
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not n or not math.isfinite(n):
        return {}
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    # mirrored into the right-handed face frame (x to the avatar's left): x kept, y and z negated
    x, y, z, w = qx, -qy, -qz, qw
    # yaw (about +Y), then pitch (about +X), then roll (about +Z): intrinsic Y-X-Z angles
    sin_p = max(-1.0, min(1.0, 2.0 * (w * x - y * z)))
    yaw = math.atan2(2.0 * (x * z + w * y), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(sin_p)
    roll = math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z))
    quarter = 0.5 * math.pi
    return {"headYaw": yaw / quarter, "headPitch": -pitch / quarter, "headRoll": -roll / quarter}


_ROTATIONS = frozenset(ROTATION_NAMES)


class BlendshapeFrames:
    """What every stream parser shares: clamp to 0..1 (rotations to -1..1; values beyond a small
    slack are counted), emit only the controls that changed, and release everything to 0 on request."""

    SLACK = 0.05

    def __init__(self, device: str, warnings: WarningCounter | None = None, mirror: bool = False) -> None:
        self.device = device
        self.warnings = warnings or WarningCounter(device)
        self.mirror = mirror
        self.frames = 0
        self.unknown: set[str] = set()
        self._last: dict[str, float] = {}

    def emit(self, values: Mapping[str, float], t: float, raw_scale: float = 1.0) -> list[ControlEvent]:
        """Events for one frame of ``{arkit name: weight}`` (weights already divided by
        ``raw_scale``; ``raw`` keeps the value as sent)."""
        self.frames += 1
        out: list[ControlEvent] = []
        for name, v in values.items():
            if not math.isfinite(v):
                self.warnings.warn("range", f"{name} = {v!r} is not a number")
                continue
            lo = -1.0 if name in _ROTATIONS else 0.0
            if not lo - self.SLACK <= v <= 1 + self.SLACK:
                self.warnings.warn("range", f"{name} = {v:g} outside {lo:g}..1; clamped")
            value = min(1.0, max(lo, v))
            if self.mirror:
                if name in FLIP_ON_MIRROR:
                    value = -value
                name = MIRRORED[name]
            if self._last.get(name, 0.0) == value:  # every blendshape starts at rest
                continue
            self._last[name] = value
            out.append(ControlEvent(self.device, name, "axis", value, None, v * raw_scale, t))
        return out

    def note_unknown(self, name: str) -> None:
        """A name the sender uses that is no ARKit blendshape (kept for `puppet monitor` users)."""
        if len(self.unknown) < 256:
            self.unknown.add(name)

    def release(self, t: float) -> list[ControlEvent]:
        """Every blendshape not at rest back to 0 (the tracker stopped sending)."""
        out = [ControlEvent(self.device, n, "axis", 0.0, None, 0.0, t) for n, v in self._last.items() if v != 0.0]
        self._last = {n: 0.0 for n in self._last}
        return out


class OscStreamParser:
    """What the OSC streams (Face Cap, VMC) share: decode a datagram, count what is not OSC."""

    def __init__(self, device: str, warnings: WarningCounter | None = None, mirror: bool = False) -> None:
        self.frames = BlendshapeFrames(device, warnings, mirror)

    def messages(self, data: bytes) -> list[Any]:
        """The datagram's OSC messages; none (counted as garbage) when it is not OSC."""
        from devices.osc import OscDecodeError, decode_packet

        try:
            return decode_packet(data)
        except OscDecodeError as err:
            self.frames.warnings.warn("garbage", f"not OSC ({err})")
            return []


class FaceStreamDevice(UdpListenerDevice):
    """A face tracker sending to a UDP port. Besides the network options (devices.udp), ``release``
    is the number of seconds without a frame after which the face is let go to neutral (1; 0 keeps
    the last pose), ``mirror=1`` swaps left and right."""

    STREAM_OPTIONS: ClassVar[frozenset[str]] = UdpListenerDevice.NET_OPTIONS | {"release", "mirror"}
    OPTIONS = STREAM_OPTIONS
    #: The stream's parser class: ``Parser(device, warnings, mirror)`` with ``feed(data, t)`` and
    #: ``frames`` (its BlendshapeFrames).
    PARSER: ClassVar[Any] = None

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        self.release_after = spec.get_float("release", 1.0, lo=0.0)
        self.controls = arkit_controls()
        self.parser = self.PARSER(self.spec, self.warnings, spec.get_bool("mirror", False))
        self.frames: BlendshapeFrames = self.parser.frames
        self._last_frame = 0.0
        self._held = False

    def _parse(self, data: bytes, t: float) -> list[ControlEvent]:
        return self.parser.feed(data, t)  # type: ignore[no-any-return]

    def _datagram(self, data: bytes, t: float, sender: str) -> list[ControlEvent]:
        before = self.frames.frames
        events = self._parse(data, t)
        if self.frames.frames != before:
            self._last_frame, self._held = t, True
        return events

    def _idle(self, t: float) -> list[ControlEvent]:
        if self._held and self.release_after > 0 and t - self._last_frame >= self.release_after:
            self._held = False
            return self.frames.release(t)
        return []

    def _read(self, timeout: float) -> Any:
        events = list(super()._read(timeout))
        if not events and self._held:  # a stream of other traffic must not hold the face forever
            events = self._idle(time.monotonic())
        return events
