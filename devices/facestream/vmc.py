"""``vmc://127.0.0.1:39539`` — the VMC protocol (VSeeFace, Waidayo, VMagicMirror...): OSC over UDP.
``/VMC/Ext/Blend/Val name weight`` messages are held until ``/VMC/Ext/Blend/Apply`` commits the
frame. Names are ARKit's ("Perfect Sync", any case) or the VRM presets below. The ``Head`` bone's
rotation (``/VMC/Ext/Bone/Pos Head px py pz qx qy qz qw``, Unity's frame) becomes the head's
rotation controls with the next Apply; other bones, the root pose and status messages are ignored."""

from __future__ import annotations

from devices.events import ControlEvent
from devices.facestream import FaceStreamDevice, OscStreamParser, arkit_name, unity_head
from devices.warn import WarningCounter

#: VRM expression presets a tracker without Perfect Sync sends, as ARKit blendshapes.
VRM_PRESETS: dict[str, tuple[str, ...]] = {
    "blink": ("eyeBlinkLeft", "eyeBlinkRight"), "blink_l": ("eyeBlinkLeft",), "blink_r": ("eyeBlinkRight",),
    "a": ("jawOpen",), "aa": ("jawOpen",), "o": ("mouthPucker",), "oh": ("mouthPucker",),
    "joy": ("mouthSmileLeft", "mouthSmileRight"), "happy": ("mouthSmileLeft", "mouthSmileRight"),
}
MAX_PENDING = 512


class VmcParser(OscStreamParser):
    """VMC datagrams -> blendshape events, one frame per Apply."""

    def __init__(self, device: str, warnings: WarningCounter | None = None, mirror: bool = False) -> None:
        super().__init__(device, warnings, mirror)
        self._pending: dict[str, float] = {}

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        out: list[ControlEvent] = []
        for m in self.messages(data):
            if m.address == "/VMC/Ext/Blend/Val":
                self._value(m.args)
            elif m.address == "/VMC/Ext/Bone/Pos" and m.args[:1] == ("Head",):
                q = m.args[4:8]
                if len(m.args) == 8 and all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in q):
                    self._pending.update(unity_head(*(float(a) for a in q)))
            elif m.address == "/VMC/Ext/Blend/Apply":
                if self._pending:
                    out += self.frames.emit(self._pending, t)
                    self._pending = {}
        return out

    def _value(self, args: tuple[Any, ...]) -> None:
        if (len(args) != 2 or not isinstance(args[0], str) or isinstance(args[1], bool)
                or not isinstance(args[1], (int, float))):
            self.frames.warnings.warn("garbage", f"/VMC/Ext/Blend/Val expects (name, weight), got {args[:3]!r}")
            return
        name = arkit_name(args[0])
        targets = (name,) if name else VRM_PRESETS.get(args[0].lower(), ())
        if not targets:
            self.frames.note_unknown(args[0][:64])
            return
        if len(self._pending) < MAX_PENDING:
            for n in targets:
                self._pending[n] = float(args[1])


class VmcDevice(FaceStreamDevice):
    """A VMC performer/assistant sending to this machine (Marionette port 39539 by default)."""

    scheme = "vmc"
    FORM = "vmc://127.0.0.1:39539[?lan=1&allow=ADDR,...&release=S&mirror=1]"
    DEFAULT_PORT = 39539
    WHAT = "VMC face tracking (OSC)"
    PARSER = VmcParser
