"""Face-tracking streams end to end over real UDP on 127.0.0.1: Face Cap and VMC (OSC),
iFacialMocap (text), Live Link Face (binary); every one yields the 52 ARKit names."""

from __future__ import annotations

import socket

import pytest
from netdev import listening, osc_bundle, osc_message

import devices
from devices.facestream import ARKIT_NAMES, MIRRORED, arkit_controls, arkit_name
from devices.facestream.facecap import FACECAP_ORDER
from devices.facestream.ifacialmocap import START_REQUEST
from devices.facestream.livelink import encode_frame


def by_control(events: list) -> dict[str, float]:
    return {e.control: e.value for e in events}


def test_the_52_names_and_the_spellings_senders_use() -> None:
    assert len(ARKIT_NAMES) == len(set(ARKIT_NAMES)) == 52
    assert sorted(FACECAP_ORDER) == sorted(ARKIT_NAMES)
    assert [c.name for c in arkit_controls()] == list(ARKIT_NAMES)
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
    # one read batch: the smile's two values coalesce to the newest
    assert by_control(got) == {"jawOpen": pytest.approx(0.6), "mouthSmileLeft": pytest.approx(0.9)}
    assert {e.control for e in got} == {"jawOpen", "mouthSmileLeft"}  # poses are no blendshapes


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
    assert by_control(got) == {"jawOpen": 0.5, "eyeBlinkLeft": 1.0}


@pytest.mark.parametrize("sep", ["-", "&"])
def test_ifacialmocap_text_frames(sep: str) -> None:
    text = (f"mouthSmile_R{sep}40|eyeBlink_L{sep}100|jawOpen{sep}12|browInnerUp{sep}0|trackingStatus{sep}1|"
            "=head#-21.4,-6.0,-6.6,-0.03,-0.1,-0.6|rightEye#6.0,2.4,0.2|leftEye#6.0,-1.6,-0.1|")
    with listening("ifacialmocap://127.0.0.1:0") as lis:
        lis.send(text.encode("ascii"))
        got = lis.events(lambda es: len(es) >= 3)
        lis.send(b"\xff\xfe not text", b"jawOpen-abc|")
        assert lis.wait_for(lambda: lis.dev.warnings.counts["garbage"] == 2)
    assert by_control(got) == {"mouthSmileRight": 0.4, "eyeBlinkLeft": 1.0, "jawOpen": 0.12}
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


def test_livelink_binary_frames() -> None:
    w = [0.0] * 52
    w[ARKIT_NAMES.index("jawOpen")] = 0.7
    w[ARKIT_NAMES.index("browDownRight")] = 0.25
    frame = encode_frame(w + [0.1] * 9, name="Performer")
    with listening("livelink://127.0.0.1:0") as lis:
        lis.send(frame[:60],  # hello / cut
                 frame[:-4], frame + b"\x00")
        lis.send(frame)
        got = lis.events(lambda es: len(es) >= 2)
        assert lis.dev.parser.subject == "Performer"
        assert lis.dev.warnings.counts["truncated"] >= 2
    assert by_control(got) == {"jawOpen": pytest.approx(0.7), "browDownRight": pytest.approx(0.25)}


def test_mirror_swaps_sides() -> None:
    w = [0.0] * 52
    w[ARKIT_NAMES.index("eyeBlinkLeft")] = 1.0
    with listening("livelink://127.0.0.1:0?mirror=1") as lis:
        lis.send(encode_frame(w))
        got = lis.events(lambda es: len(es) >= 1)
    assert by_control(got) == {"eyeBlinkRight": 1.0}


def test_a_stream_that_stops_lets_the_face_go() -> None:
    w = [0.0] * 52
    w[ARKIT_NAMES.index("mouthSmileLeft")] = 0.8
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
