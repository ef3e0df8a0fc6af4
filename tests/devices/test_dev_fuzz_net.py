"""The network parsers fed random and mutated datagrams (hypothesis), like the serial ones in
test_dev_fuzz.py: no exception escapes, values stay finite and inside declared ranges, buttons are
0/1, and a valid datagram after any garbage still decodes."""

from __future__ import annotations

import math
import struct

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from netdev import osc_bundle, osc_message
from test_dev_fuzz import edits, mutate  # the serial fuzzers' byte edits

from devices.events import ControlEvent
from devices.facestream import ARKIT_NAMES, ROTATION_NAMES
from devices.facestream.facecap import FaceCapParser
from devices.facestream.ifacialmocap import IFacialMocapParser
from devices.facestream.livelink import LiveLinkParser, encode_frame
from devices.facestream.vmc import VmcParser
from devices.osc import PROFILES, OscDecodeError, OscParser, decode_packet

FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
ARKIT = set(ARKIT_NAMES)
ROTATIONS = set(ROTATION_NAMES)


def check_osc(events: list[ControlEvent], profile: str) -> None:
    prof = PROFILES[profile]
    for e in events:
        assert math.isfinite(e.value) and e.control.startswith("/")
        if e.kind == "button":
            assert e.value in (0.0, 1.0)
        else:
            assert e.kind == "axis"
            info = prof.declared(e.control)
            if info is not None:
                assert info.kind == "axis" and info.lo <= e.value <= info.hi


def check_arkit(events: list[ControlEvent]) -> None:
    for e in events:
        assert e.kind == "axis" and (e.control in ARKIT and 0.0 <= e.value <= 1.0
                                     or e.control in ROTATIONS and -1.0 <= e.value <= 1.0)


SAMPLES = [
    osc_message("/1/fader1", 0.5), osc_message("/3/xy", 0.2, 0.8), osc_message("/2/push1", 1.0),
    osc_message("/face/channel/jaw", 0.8), osc_message("/x", True, "s", b"blob", 3),
    osc_bundle([osc_message("/fader_1", 0.3), osc_message("/button_2")]),
    osc_bundle([osc_message("/W", 24, 0.5), osc_message("/W", 3, 0.1)]),
    osc_bundle([osc_message("/VMC/Ext/Blend/Val", "jawOpen", 0.4), osc_message("/VMC/Ext/Blend/Apply")]),
]


@FUZZ
@given(st.binary(max_size=400), st.sampled_from(sorted(PROFILES)))
def test_osc_random_datagrams(data: bytes, profile: str) -> None:
    p = OscParser("osc://t", PROFILES[profile])
    check_osc(p.feed(data, 1.0), profile)
    after = p.feed(osc_message("/after", 0.5), 2.0)
    assert [(e.control, e.value) for e in after] == [("/after", 0.5)]


@FUZZ
@given(st.sampled_from(SAMPLES), edits, st.sampled_from(sorted(PROFILES)))
def test_osc_mutated_datagrams(data: bytes, ops: list[tuple[int, int, int]], profile: str) -> None:
    p = OscParser("osc://t", PROFILES[profile])
    check_osc(p.feed(mutate(data, ops), 1.0), profile)


@FUZZ
@given(st.sampled_from(SAMPLES), edits)
def test_decode_packet_raises_only_its_own_error(data: bytes, ops: list[tuple[int, int, int]]) -> None:
    try:
        msgs = decode_packet(mutate(data, ops))
    except OscDecodeError:
        return
    assert all(isinstance(m.address, str) for m in msgs)


@FUZZ
@given(st.lists(st.tuples(st.integers(-5, 60), st.floats(allow_nan=True, allow_infinity=True, width=32)), max_size=60),
       edits)
def test_facecap_fuzz(weights: list[tuple[int, float]], ops: list[tuple[int, int, int]]) -> None:
    p = FaceCapParser("facecap://t")
    data = osc_bundle([osc_message("/W", i, v) for i, v in weights]) if weights else b""
    check_arkit(p.feed(data, 1.0))
    check_arkit(p.feed(mutate(data, ops), 2.0))


@FUZZ
@given(st.lists(st.tuples(st.sampled_from([*ARKIT_NAMES, "Blink", "A", "nope", ""]),
                          st.floats(-2, 2, allow_nan=False)), max_size=40), edits)
def test_vmc_fuzz(pairs: list[tuple[str, float]], ops: list[tuple[int, int, int]]) -> None:
    p = VmcParser("vmc://t")
    msgs = [osc_message("/VMC/Ext/Blend/Val", n, v) for n, v in pairs] + [osc_message("/VMC/Ext/Blend/Apply")]
    data = osc_bundle(msgs)
    check_arkit(p.feed(data, 1.0))
    check_arkit(p.feed(mutate(data, ops), 2.0))


@FUZZ
@given(st.text(max_size=300), st.binary(max_size=300))
def test_ifacialmocap_fuzz(text: str, junk: bytes) -> None:
    p = IFacialMocapParser("ifacialmocap://t")
    check_arkit(p.feed(text.encode("utf-8", "replace"), 1.0))
    check_arkit(p.feed(junk, 2.0))
    good = p.feed(b"jawOpen-50|mouthSmile_L-25|=head#1,2,3,4,5,6|", 3.0)
    assert {e.control: e.value for e in good}.get("mouthSmileLeft", 0.25) == 0.25


@FUZZ
@given(st.binary(min_size=52 * 4, max_size=61 * 4), edits, st.binary(max_size=120))
def test_livelink_fuzz(floats: bytes, ops: list[tuple[int, int, int]], junk: bytes) -> None:
    p = LiveLinkParser("livelink://t")
    weights = struct.unpack(f">{len(floats) // 4}f", floats[: len(floats) // 4 * 4])  # any float32, NaN too
    frame = encode_frame(list(weights))
    check_arkit(p.feed(frame, 1.0))
    check_arkit(p.feed(mutate(frame, ops), 2.0))
    check_arkit(p.feed(junk, 3.0))
