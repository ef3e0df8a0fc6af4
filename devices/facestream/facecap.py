"""``facecap://127.0.0.1:8080`` — Face Cap (iOS) live mode: OSC over UDP, one ``/W i f`` message per
blendshape (index in Face Cap's own order, weight 0..1), plus the head's position (``/HT``, not
used) and rotation (``/HR x y z``) and the eyes' rotations (``/ELR x y``, ``/ERR x y``), Euler
degrees about ARKit's face axes, which become the rotation controls (``headYaw``, ``leftEyePitch``...)."""

from __future__ import annotations

from devices.events import ControlEvent
from devices.facestream import FaceStreamDevice, OscStreamParser, arkit_euler

#: Face Cap's blendshape order (``/W`` index -> ARKit name).
FACECAP_ORDER = (
    "browInnerUp", "browDownLeft", "browDownRight", "browOuterUpLeft", "browOuterUpRight", "eyeLookUpLeft",
    "eyeLookUpRight", "eyeLookDownLeft", "eyeLookDownRight", "eyeLookInLeft", "eyeLookInRight", "eyeLookOutLeft",
    "eyeLookOutRight", "eyeBlinkLeft", "eyeBlinkRight", "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft",
    "eyeWideRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight",
    "jawOpen", "jawForward", "jawLeft", "jawRight", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    "mouthRollUpper", "mouthRollLower", "mouthShrugUpper", "mouthShrugLower", "mouthClose", "mouthSmileLeft",
    "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight",
    "mouthUpperUpLeft", "mouthUpperUpRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthPressLeft",
    "mouthPressRight", "mouthStretchLeft", "mouthStretchRight", "tongueOut",
)
POSES = frozenset({"/HT", "/HR", "/ELR", "/ERR"})
ROTATIONS = {"/HR": "head", "/ELR": "leftEye", "/ERR": "rightEye"}


def _numbers(args: tuple) -> list[float] | None:
    if all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in args):
        return [float(a) for a in args]
    return None


class FaceCapParser(OscStreamParser):
    """Face Cap datagrams -> blendshape events."""

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        values: dict[str, float] = {}
        for m in self.messages(data):
            if m.address == "/W":
                if (len(m.args) == 2 and isinstance(m.args[0], int) and not isinstance(m.args[0], bool)
                        and isinstance(m.args[1], (int, float)) and not isinstance(m.args[1], bool)):
                    if 0 <= m.args[0] < len(FACECAP_ORDER):
                        values[FACECAP_ORDER[m.args[0]]] = float(m.args[1])
                        continue
                self.frames.warnings.warn("garbage", f"/W expects (index 0..51, weight), got {m.args[:3]!r}")
            elif m.address in ROTATIONS:
                xyz = _numbers(m.args)
                if xyz is None or len(xyz) not in (2, 3):
                    self.frames.warnings.warn("garbage", f"{m.address} expects 2 or 3 angles, got {m.args[:4]!r}")
                    continue
                values.update(arkit_euler(ROTATIONS[m.address], *(xyz + [0.0])[:3]))
            elif m.address not in POSES:
                self.frames.note_unknown(m.address)
        return self.frames.emit(values, t) if values else []


class FaceCapDevice(FaceStreamDevice):
    """Face Cap's live mode (set the phone's target to this machine and port 8080)."""

    scheme = "facecap"
    FORM = "facecap://127.0.0.1:8080[?lan=1&allow=ADDR,...&release=S&mirror=1]"
    DEFAULT_PORT = 8080
    WHAT = "Face Cap face tracking (OSC)"
    PARSER = FaceCapParser
