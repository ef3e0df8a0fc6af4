"""Every parser fed random and mutated streams: no exception escapes, every value stays inside its
control's declared range, and only declared controls appear."""

from __future__ import annotations

import can
import cantools
from devdata import BJM1_DBC as BJM1
from devdata import MAPLE_RDESC, MAPLE_REPORT, ROLLER_EVENTS, ROLLER_RDESC
from devdata import PANEL_DBC as PANEL
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices.base import ControlInfo
from devices.candev import CanDecoder
from devices.controlsets import sgi_controls, text_controls
from devices.events import ControlEvent
from devices.firmata import FirmataParser
from devices.hid.descriptor import DescriptorError, GenericDecoder, ReportDescriptor
from devices.hid.profiles import PowerMateProfile, ShuttleProfile, XkeysProfile
from devices.sgi import SgiParser, button_code
from devices.textserial import TextParser
from devices.warn import WarningCounter

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def check(events: list[ControlEvent], controls: list[ControlInfo]) -> None:
    declared = {c.name: c for c in controls}
    for e in events:
        info = declared[e.control]
        assert e.kind == info.kind
        assert info.lo <= e.value <= info.hi, (e, info)
        if e.kind in ("button", "key"):
            assert e.value in (0.0, 1.0)


def chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in zip(points, points[1:])]


def mutate(data: bytes, edits: list[tuple[int, int, int]]) -> bytes:
    """Apply (op, position, byte) edits: 0 flip a byte, 1 insert, 2 delete."""
    b = bytearray(data)
    for op, pos, val in edits:
        if not b and op != 1:
            continue
        i = pos % (len(b) + (op == 1))
        if op == 0:
            b[i] = val
        elif op == 1:
            b.insert(i, val)
        else:
            del b[i]
    return bytes(b)


edits = st.lists(st.tuples(st.integers(0, 2), st.integers(0, 10_000), st.integers(0, 255)), max_size=12)


def sgi_stream(moves: list[tuple[int, int]]) -> bytes:
    counters = [0] * 8
    out = bytearray()
    for kind, n in moves:
        if kind < 8:
            counters[kind] = (counters[kind] + n + 0x8000) % 0x10000 - 0x8000
            out += bytes([0x30 + kind, (counters[kind] >> 8) & 0xFF, counters[kind] & 0xFF])
        else:
            out.append(button_code(n % 32, kind == 8))
    return bytes(out)


moves = st.lists(st.tuples(st.integers(0, 9), st.integers(-150, 150)), max_size=40)


@FUZZ
@given(st.binary(max_size=300), st.lists(st.integers(0, 400), max_size=6))
def test_sgi_random_bytes(data: bytes, cuts: list[int]) -> None:
    p = SgiParser("f", 200, WarningCounter("f", interval=3600))
    for chunk in chunks(data, cuts):
        check(p.feed(chunk, 0.0), sgi_controls())


@FUZZ
@given(moves, edits)
def test_sgi_mutated_streams_keep_their_sums_when_clean(m: list[tuple[int, int]], e: list[tuple[int, int, int]]) -> None:
    stream = sgi_stream(m)
    p = SgiParser("f", 200, WarningCounter("f", interval=3600))
    out = p.feed(mutate(stream, e), 0.0)
    check(out, sgi_controls())
    if not e:  # an intact stream: every count arrives
        for n in range(8):
            assert sum(ev.delta for ev in out if ev.control == f"dial{n}") == sum(c for k, c in m if k == n)


text_lines = st.lists(st.one_of(
    st.builds(lambda k, n, v: f"{k}{n} {v}\n", st.sampled_from("BDAXL"), st.integers(0, 20),
              st.one_of(st.integers(-50, 50).map(str), st.floats(allow_nan=True).map(str), st.sampled_from(["", "+", "1e9", "0x1"]))),
    st.binary(max_size=30).map(lambda b: b.decode("latin-1"))), max_size=20)


@FUZZ
@given(text_lines, edits, st.lists(st.integers(0, 500), max_size=5))
def test_text_protocol_random_and_mutated(lines: list[str], e: list[tuple[int, int, int]], cuts: list[int]) -> None:
    data = mutate("".join(lines).encode("latin-1"), e)
    p = TextParser("f", 16, 8, 8, 24, WarningCounter("f", interval=3600))
    for chunk in chunks(data, cuts):
        check(p.feed(chunk, 0.0), text_controls())


@FUZZ
@given(st.binary(max_size=300), edits)
def test_firmata_random_and_mutated(data: bytes, e: list[tuple[int, int, int]]) -> None:
    valid = bytes([0xE0, 0x10, 0x07, 0x90, 0x7F, 0x01, 0xF0, 0x61, 0x40, 0x05, 0, 0, 0, 0xF7, 0xF9, 2, 5])
    p = FirmataParser("f", list(range(16)), list(range(128)), True, 10, 96, WarningCounter("f", interval=3600))
    controls = ([ControlInfo(f"axis{n}", "axis") for n in range(16)] + [ControlInfo(f"button{n}", "button") for n in range(128)]
                + [ControlInfo(f"dial{n}", "dial", -1, 1) for n in range(64)])
    check(p.feed(data, 0.0), controls)
    check(p.feed(mutate(valid * 3, e), 0.0), controls)


@FUZZ
@given(st.sampled_from([MAPLE_RDESC, ROLLER_RDESC]), edits, st.lists(st.binary(max_size=20), max_size=8))
def test_hid_descriptors_mutated_and_random_reports(desc: bytes, e: list[tuple[int, int, int]], reports: list[bytes]) -> None:
    try:
        parsed = ReportDescriptor.parse(mutate(desc, e))
    except DescriptorError:
        return
    dec = GenericDecoder("f", parsed, warnings=WarningCounter("f", interval=3600))
    for r in [MAPLE_REPORT, *ROLLER_EVENTS, *reports]:
        check(dec.decode(r, 0.0), dec.controls)


@FUZZ
@given(st.binary(max_size=600))
def test_hid_random_descriptors(desc: bytes) -> None:
    try:
        parsed = ReportDescriptor.parse(desc)
    except DescriptorError:
        return
    dec = GenericDecoder("f", parsed, warnings=WarningCounter("f", interval=3600))
    for rid in list(parsed.report_bytes)[:4]:
        check(dec.decode(bytes([rid]) + bytes(range(64)), 0.0), dec.controls)


@FUZZ
@given(st.lists(st.binary(max_size=40), max_size=20))
def test_hid_profiles_random_reports(reports: list[bytes]) -> None:
    w = WarningCounter("f", interval=3600)
    for profile in (PowerMateProfile("f", w), ShuttleProfile("f", w), ShuttleProfile("f", w, pro=True),
                    XkeysProfile("f", w, model=("XK-80", 10, 8))):
        for r in reports:
            check(profile.decode(r, 0.0), profile.controls)


_DBS = [cantools.database.load_file(PANEL), cantools.database.load_file(BJM1)]


@FUZZ
@given(st.sampled_from([0, 1]), st.lists(st.tuples(st.sampled_from([0x100, 0x101, 0x102, 0x0CFDD6AA, 0x7FF, 0x4]),
                                                   st.binary(max_size=8), st.booleans()), max_size=30))
def test_can_random_frames(which: int, frames: list[tuple[int, bytes, bool]]) -> None:
    dec = CanDecoder("f", _DBS[which], WarningCounter("f", interval=3600))
    for fid, data, err in frames:
        msg = can.Message(arbitration_id=fid, data=data, is_extended_id=fid > 0x7FF, is_error_frame=err and fid == 0x4)
        check(dec.decode(msg, 0.0), dec.controls)


scalars = st.one_of(st.integers(-1000, 1000), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6),
                    st.booleans(), st.none())
entry = st.dictionaries(st.sampled_from(["t", "control", "value", "delta", "start", "duration", "rate", "from", "to",
                                         "freq", "amplitude", "offset", "period", "duty", "count", "status", "kind",
                                         "name", "lo", "hi"]),
                        st.one_of(scalars, st.sampled_from(["dial0", "button3", "x", "key:A", "lost"])), max_size=8)
script = st.dictionaries(st.sampled_from(["events", "ramp", "sine", "pattern", "status", "controls", "impersonate",
                                          "speed", "loop", "counts_per_turn", "duration"]),
                         st.one_of(st.lists(entry, max_size=3), scalars, st.sampled_from(["sgi", "nope"])), max_size=6)


@FUZZ
@given(script)
def test_mock_scripts_fail_cleanly_or_stay_in_range(data: dict[str, object]) -> None:
    import json

    from devices.errors import DeviceSpecError
    from devices.mock import build_script

    try:
        s = build_script(json.loads(json.dumps(data, default=str)), "fuzz")
    except DeviceSpecError:
        return  # the only way a bad script may fail
    for it in s.items:
        if not it.status:
            info = s.controls[it.control]
            assert info.lo <= it.value <= info.hi
