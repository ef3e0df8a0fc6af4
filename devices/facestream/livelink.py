"""``livelink://127.0.0.1:11111`` — Epic's Live Link Face (iOS): one binary UDP datagram per frame.

Layout (integers and floats big-endian except the first): uint32 packet version (little-endian),
37 bytes device id, int32 subject-name length + the name (UTF-8), int32 frame number, float32
sub-frame, int32 frame rate numerator and denominator, uint8 count (61), then ``count`` float32
in the order of Unreal's ``EARFaceBlendShape`` enum (`WIRE_ORDER`): the 52 blendshapes, then head
yaw, pitch, roll and the left and right eyes' yaw, pitch, roll (-1..1). That order is not the
CSV's: the enum has JawLeft (15) before JawRight (16) and MouthLeft (21) before MouthRight (22).
A datagram without the frame part (the app's "hello") carries no values."""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence

from devices.events import ControlEvent
from devices.facestream import ARKIT_NAMES, ROTATION_NAMES, BlendshapeFrames, FaceStreamDevice
from devices.warn import WarningCounter

_SWAP = {"jawLeft": "jawRight", "jawRight": "jawLeft", "mouthLeft": "mouthRight", "mouthRight": "mouthLeft"}
#: The 61 values of a packet, by index: the CSV's order with the two sideways pairs the enum's way.
WIRE_ORDER: tuple[str, ...] = (*(_SWAP.get(n, n) for n in ARKIT_NAMES), *ROTATION_NAMES)

HEADER = 45  # version + device id + name length
FRAME = struct.Struct(">ifiiB")
MAX_NAME = 256


def encode_frame(weights: Mapping[str, float] | Sequence[float], name: str = "iPhone", frame: int = 0,
                 fps: int = 60, device_id: str = "$00000000-0000-0000-0000-000000000000",
                 version: int = 6) -> bytes:
    """A Live Link Face datagram (for tests, benchmarks and rehearsal senders). ``weights`` maps
    ARKit and rotation names (``jawLeft``, ``headYaw``) to values, the rest 0; a plain sequence is
    taken in `WIRE_ORDER`."""
    if isinstance(weights, Mapping):
        unknown = set(weights) - set(WIRE_ORDER)
        if unknown:
            raise ValueError(f"not Live Link values: {', '.join(sorted(unknown))}")
        values = [float(weights.get(n, 0.0)) for n in WIRE_ORDER]
    else:
        values = list(weights) + [0.0] * (61 - len(weights))
    body = name.encode("utf-8")
    return (struct.pack("<I", version) + device_id.encode("ascii")[:37].ljust(37, b"0")
            + struct.pack(">i", len(body)) + body + FRAME.pack(frame, 0.0, fps, 1, 61)
            + struct.pack(">61f", *values))


class LiveLinkParser:
    """Live Link Face datagrams -> blendshape events."""

    def __init__(self, device: str, warnings: WarningCounter | None = None, mirror: bool = False) -> None:
        self.frames = BlendshapeFrames(device, warnings, mirror)
        self.subject = ""

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        warn = self.frames.warnings.warn
        if len(data) < HEADER:
            warn("garbage", f"{len(data)}-byte datagram is no Live Link packet")
            return []
        (name_len,) = struct.unpack_from(">i", data, 41)
        end = HEADER + name_len
        if not 0 <= name_len <= MAX_NAME or end > len(data):
            warn("garbage", f"subject name of {name_len} bytes does not fit the datagram")
            return []
        if len(data) == end:
            return []  # a hello without a frame
        if len(data) < end + FRAME.size:
            warn("truncated", "frame header cut short")
            return []
        count = FRAME.unpack_from(data, end)[4]
        body = end + FRAME.size
        if count < len(ARKIT_NAMES) or len(data) != body + 4 * count:
            warn("truncated", f"{count} values announced, {(len(data) - body) // 4} present (52 or more expected)")
            return []
        self.subject = data[HEADER:end].decode("utf-8", "replace")
        n = min(count, len(WIRE_ORDER))
        values = struct.unpack_from(f">{n}f", data, body)
        return self.frames.emit(dict(zip(WIRE_ORDER, values)), t)


class LiveLinkDevice(FaceStreamDevice):
    """Live Link Face streaming to this machine (the app's target: this address, port 11111)."""

    scheme = "livelink"
    FORM = "livelink://127.0.0.1:11111[?lan=1&allow=ADDR,...&release=S&mirror=1]"
    DEFAULT_PORT = 11111
    WHAT = "Live Link Face face tracking"
    PARSER = LiveLinkParser
