"""Face-tracking streams end to end over real UDP on 127.0.0.1: Face Cap and VMC (OSC),
iFacialMocap (text), Live Link Face (binary); every one yields the 52 ARKit names."""

from __future__ import annotations

import socket
import struct

import pytest
from netdev import listening, osc_bundle, osc_message

import devices
from devices.facestream import ARKIT_NAMES, MIRRORED, ROTATION_NAMES, arkit_controls, arkit_name
from devices.facestream.facecap import FACECAP_ORDER
from devices.facestream.ifacialmocap import START_REQUEST
from devices.facestream.livelink import LiveLinkParser, encode_frame

#: Unreal's EARFaceBlendShape enum as published in Epic's API reference (ARTrackable.h), index by
#: index: the order of a Live Link Face packet's 61 floats. Written out here, not taken from the code.
UNREAL_ENUM = """EyeBlinkLeft EyeLookDownLeft EyeLookInLeft EyeLookOutLeft EyeLookUpLeft EyeSquintLeft EyeWideLeft
EyeBlinkRight EyeLookDownRight EyeLookInRight EyeLookOutRight EyeLookUpRight EyeSquintRight EyeWideRight
JawForward JawLeft JawRight JawOpen MouthClose MouthFunnel MouthPucker MouthLeft MouthRight
MouthSmileLeft MouthSmileRight MouthFrownLeft MouthFrownRight MouthDimpleLeft MouthDimpleRight
MouthStretchLeft MouthStretchRight MouthRollLower MouthRollUpper MouthShrugLower MouthShrugUpper
MouthPressLeft MouthPressRight MouthLowerDownLeft MouthLowerDownRight MouthUpperUpLeft MouthUpperUpRight
BrowDownLeft BrowDownRight BrowInnerUp BrowOuterUpLeft BrowOuterUpRight CheekPuff CheekSquintLeft
CheekSquintRight NoseSneerLeft NoseSneerRight TongueOut HeadYaw HeadPitch HeadRoll
LeftEyeYaw LeftEyePitch LeftEyeRoll RightEyeYaw RightEyePitch RightEyeRoll""".split()


def by_control(events: list) -> dict[str, float]:
    return {e.control: e.value for e in events}


def test_the_52_names_and_the_spellings_senders_use() -> None:
    assert len(ARKIT_NAMES) == len(set(ARKIT_NAMES)) == 52
    assert sorted(FACECAP_ORDER) == sorted(ARKIT_NAMES)
    assert [c.name for c in arkit_controls()] == [*ARKIT_NAMES, *ROTATION_NAMES]
    assert {(c.lo, c.hi) for c in arkit_controls()[52:]} == {(-1.0, 1.0)}
    assert arkit_name("EyeBlinkLeft") == arkit_name("eyeBlink_L") == arkit_name("EYEBLINKLEFT") == "eyeBlinkLeft"
    assert arkit_name("mouthSmile_R") == "mouthSmileRight" and arkit_name("jawOpen") == "jawOpen"
    assert arkit_name("Joy") is None and arkit_name("") is None
    assert MIRRORED["browDownLeft"] == "browDownRight" and MIRRORED["tongueOut"] == "tongueOut"
    assert all(MIRRORED[MIRRORED[n]] == n for n in ARKIT_NAMES)


def test_facecap_index_messages() -> None:
    jaw, smile_l = FACECAP_ORDER.index("jawOpen"), FACECAP_ORDER.index("mouthSmileLeft")
    frame = osc_bundle([osc_message("/W", jaw, 0.6), osc_message("/W", smile_l, 0.3),
                        osc_message("/HR", 1.0, 2.0, 3.0), osc_message("/ELR", 1.0, 2.0)])
    with listening("facecap://127.0.0.1:0") as lis:
        assert lis.dev.control("tongueOut").kind == "axis"
        lis.send(frame, osc_message("/W", 99, 0.5), osc_message("/W", "x", 0.5), osc_message("/W", smile_l, 0.9))
        got = lis.events(lambda es: any(e.control == "mouthSmileLeft" and e.value > 0.8 for e in es))
        assert lis.dev.warnings.counts["garbage"] == 2
    # one read batch: the smile's two values coalesce to the newest; the head's and the left eye's
    # Euler degrees become rotations (90 degrees = 1; ARKit's +x turns the nose down, +z the crown right)
    assert by_control(got) == {"jawOpen": pytest.approx(0.6), "mouthSmileLeft": pytest.approx(0.9),
                               "headPitch": pytest.approx(-1 / 90), "headYaw": pytest.approx(2 / 90),
                               "headRoll": pytest.approx(-3 / 90), "leftEyePitch": pytest.approx(-1 / 90),
                               "leftEyeYaw": pytest.approx(2 / 90)}


def test_vmc_values_wait_for_apply() -> None:
    vals = [osc_message("/VMC/Ext/Blend/Val", "JawOpen", 0.5), osc_message("/VMC/Ext/Blend/Val", "Blink_L", 1.0),
            osc_message("/VMC/Ext/Blend/Val", "Neutral", 1.0), osc_message("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0,
                                                                           0.0, 0.0, 0.0, 1.0)]
    with listening("vmc://127.0.0.1:0") as lis:
        lis.send(osc_bundle(vals))
        assert lis.wait_for(lambda: lis.dev.datagrams == 1)
        assert not [e for e in lis.q.drain() if hasattr(e, "control")]  # held until Apply
        lis.send(osc_bundle([osc_message("/VMC/Ext/Blend/Apply")]))
        got = lis.events(lambda es: len(es) >= 2)
        assert "Neutral" in lis.dev.frames.unknown
    assert by_control(got) == {"jawOpen": 0.5, "eyeBlinkLeft": 1.0}  # the head bone at rest: no turn


def test_vmc_head_bone_turns_the_head() -> None:
    """A head bone turned 18 degrees about Unity's up axis (towards the avatar's right, +x) is a
    head turned to the face's right: headYaw -0.2."""
    import math
    half = math.radians(18.0) / 2
    bone = osc_message("/VMC/Ext/Bone/Pos", "Head", 0.0, 1.5, 0.0, 0.0, math.sin(half), 0.0, math.cos(half))
    with listening("vmc://127.0.0.1:0") as lis:
        lis.send(osc_bundle([bone, osc_message("/VMC/Ext/Blend/Apply")]))
        got = lis.events(lambda es: len(es) >= 1)
    assert by_control(got) == {"headYaw": pytest.approx(-0.2)}


@pytest.mark.parametrize("sep", ["-", "&"])
def test_ifacialmocap_text_frames(sep: str) -> None:
    text = (f"mouthSmile_R{sep}40|eyeBlink_L{sep}100|jawOpen{sep}12|browInnerUp{sep}0|trackingStatus{sep}1|"
            "=head#-21.4,-6.0,-6.6,-0.03,-0.1,-0.6|rightEye#6.0,2.4,0.2|leftEye#6.0,-1.6,-0.1|")
    with listening("ifacialmocap://127.0.0.1:0") as lis:
        lis.send(text.encode("ascii"))
        got = lis.events(lambda es: len(es) >= 12)
        lis.send(b"\xff\xfe not text", b"jawOpen-abc|")
        assert lis.wait_for(lambda: lis.dev.warnings.counts["garbage"] == 2)
    assert by_control(got) == {"mouthSmileRight": 0.4, "eyeBlinkLeft": 1.0, "jawOpen": 0.12,
                               "headPitch": pytest.approx(21.4 / 90), "headYaw": pytest.approx(-6.0 / 90),
                               "headRoll": pytest.approx(6.6 / 90), "rightEyePitch": pytest.approx(-6.0 / 90),
                               "rightEyeYaw": pytest.approx(2.4 / 90), "rightEyeRoll": pytest.approx(-0.2 / 90),
                               "leftEyePitch": pytest.approx(-6.0 / 90), "leftEyeYaw": pytest.approx(-1.6 / 90),
                               "leftEyeRoll": pytest.approx(0.1 / 90)}
    assert got[0].raw == 40.0  # the value as sent, 0..100


def test_ifacialmocap_asks_the_phone_to_start() -> None:
    phone = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    phone.bind(("127.0.0.1", 0))
    phone.settimeout(5)
    try:
        with listening(f"ifacialmocap://127.0.0.1:0?phone=127.0.0.1:{phone.getsockname()[1]}") as lis:
            data, addr = phone.recvfrom(1024)
            assert data == START_REQUEST and addr[1] == lis.port  # so the phone answers to the listener
    finally:
        phone.close()
    with pytest.raises(devices.DeviceSpecError, match="lan=1"):
        devices.open_device("ifacialmocap://127.0.0.1:0?phone=192.168.1.30")
    with pytest.raises(devices.DeviceSpecError, match="IP"):
        devices.open_device("ifacialmocap://127.0.0.1:0?phone=my-phone")


def handmade_packet(values: dict[str, float], subject: str = "Phone") -> bytes:
    """A Live Link Face datagram packed by hand from the published enum order."""
    floats = [values.get(n, 0.0) for n in UNREAL_ENUM]
    name = subject.encode()
    return (struct.pack("<I", 6) + b"$" + b"1" * 36 + struct.pack(">i", len(name)) + name
            + struct.pack(">ifiiB", 7, 0.0, 60, 1, 61) + struct.pack(">61f", *floats))


def test_livelink_packet_follows_unreals_enum_order() -> None:
    """Each sideways shape arrives as itself: JawLeft is float 15, MouthRight float 22; the head
    and eye rotations come through as the rotation controls."""
    assert len(UNREAL_ENUM) == 61
    sent = {"JawLeft": 0.75, "MouthRight": 0.5, "MouthPucker": 0.25, "TongueOut": 0.125,
            "HeadYaw": -0.25, "HeadRoll": 0.125, "LeftEyePitch": 0.0625}
    got = by_control(LiveLinkParser("livelink://t").feed(handmade_packet(sent), 1.0))
    assert got == {k[0].lower() + k[1:]: v for k, v in sent.items()}
    # the project's own encoder writes what the enum says, too
    assert encode_frame({k[0].lower() + k[1:]: v for k, v in sent.items()}, name="Phone", frame=7,
                        device_id="$" + "1" * 36) == handmade_packet(sent)


def test_livelink_from_a_third_party_encoder() -> None:
    """pylivelinkface (a Python Live Link Face sender) packs the same values the same way."""
    pllf = pytest.importorskip("pylivelinkface")
    face = pllf.PyLiveLinkFace(name="Py", uuid="$" + "2" * 36)
    sent = {"JawLeft": 0.5, "JawRight": 0.0, "MouthLeft": 0.25, "MouthFunnel": 0.75, "HeadPitch": 0.25}
    for k, v in sent.items():
        face.set_blendshape(pllf.FaceBlendShape[k], v, no_filter=True)
    got = by_control(LiveLinkParser("livelink://t").feed(face.encode(), 1.0))
    assert got == {k[0].lower() + k[1:]: v for k, v in sent.items() if v}


def test_livelink_binary_frames() -> None:
    w = {"jawOpen": 0.7, "browDownRight": 0.25}
    frame = encode_frame(w, name="Performer")
    with listening("livelink://127.0.0.1:0") as lis:
        lis.send(frame[:60],  # hello / cut
                 frame[:-4], frame + b"\x00")
        lis.send(frame)
        got = lis.events(lambda es: len(es) >= 2)
        assert lis.dev.parser.subject == "Performer"
        assert lis.dev.warnings.counts["truncated"] >= 2
    assert by_control(got) == {"jawOpen": pytest.approx(0.7), "browDownRight": pytest.approx(0.25)}


def test_mirror_swaps_sides() -> None:
    w = {"eyeBlinkLeft": 1.0, "headYaw": 0.25, "headPitch": 0.125, "leftEyeYaw": 0.5}
    with listening("livelink://127.0.0.1:0?mirror=1") as lis:
        lis.send(encode_frame(w))
        got = lis.events(lambda es: len(es) >= 4)
    # a mirror turns yaw the other way and swaps the eyes; pitch stays
    assert by_control(got) == {"eyeBlinkRight": 1.0, "headYaw": -0.25, "headPitch": 0.125, "rightEyeYaw": -0.5}


def test_a_stream_that_stops_lets_the_face_go() -> None:
    w = {"mouthSmileLeft": 0.8}
    with listening("livelink://127.0.0.1:0?release=0.2") as lis:
        lis.send(encode_frame(w))
        got = lis.events(lambda es: any(e.value == 0.0 for e in es))
    assert [(e.control, e.value) for e in got] == [("mouthSmileLeft", pytest.approx(0.8)), ("mouthSmileLeft", 0.0)]


def test_values_outside_0_1_are_clamped_and_counted() -> None:
    with listening("vmc://127.0.0.1:0") as lis:
        lis.send(osc_bundle([osc_message("/VMC/Ext/Blend/Val", "jawOpen", 1.5),
                             osc_message("/VMC/Ext/Blend/Val", "mouthClose", float("nan")),
                             osc_message("/VMC/Ext/Blend/Apply")]))
        got = lis.events(lambda es: len(es) >= 1)
        assert lis.dev.warnings.counts["range"] == 2
    assert by_control(got) == {"jawOpen": 1.0}


@pytest.mark.parametrize("scheme,port", [("facecap", 8080), ("vmc", 39539), ("ifacialmocap", 49983),
                                         ("livelink", 11111)])
def test_default_ports_and_localhost(scheme: str, port: int) -> None:
    cls = devices.backend_class(scheme)
    dev = cls(devices.parse_spec(f"{scheme}://"))
    try:
        assert (dev.host, dev.port) == ("127.0.0.1", port)
    finally:
        dev.close()
    with pytest.raises(devices.DeviceSpecError, match="lan=1"):
        devices.open_device(f"{scheme}://0.0.0.0:{port}")
