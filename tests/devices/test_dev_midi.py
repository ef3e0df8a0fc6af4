"""The MIDI tokenizer, the profile decoder, the profile files and the lights' feedback rules."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices.events import ControlEvent
from devices.midi.decoder import MidiDecoder, relative_delta
from devices.midi.feedback import Feedback
from devices.midi.profile import ProfileError, load_profile, parse_profile, profile_for_port, profile_names
from devices.midi.tokenizer import REALTIME, MidiTokenizer, message_length
from devices.warn import WarningCounter


def tok(data: bytes | list[int], cap: int = 4096) -> tuple[list[tuple[int, ...]], MidiTokenizer]:
    t = MidiTokenizer("t", sysex_cap=cap, warnings=WarningCounter("t", interval=3600))
    return [m for m, _ in t.feed(bytes(data), 0.0)], t


# ------------------------------------------------------------------------------------ tokenizer
def test_running_status_gives_every_message() -> None:
    msgs, _ = tok([0xB0, 0x10, 0x40, 0x10, 0x41, 0x11, 0x42])
    assert msgs == [(0xB0, 0x10, 0x40), (0xB0, 0x10, 0x41), (0xB0, 0x11, 0x42)]


@pytest.mark.parametrize("stream, want", [
    ([0xB0, 0xF8, 0x10, 0x40], [(0xF8,), (0xB0, 0x10, 0x40)]),
    ([0xB0, 0x10, 0xF8, 0x40], [(0xF8,), (0xB0, 0x10, 0x40)]),
    ([0x90, 0x3C, 0x64, 0xF8, 0x40, 0x7F], [(0x90, 0x3C, 0x64), (0xF8,), (0x90, 0x40, 0x7F)]),
    ([0x90, 0x3C, 0xFE, 0x64], [(0xFE,), (0x90, 0x3C, 0x64)]),
    ([0xF0, 0x01, 0xF8, 0x02, 0xF7], [(0xF8,), (0xF0, 0x01, 0x02, 0xF7)]),
    ([0x90, 0x3C, 0xF9, 0x64, 0xFD, 0x40, 0x7F], [(0x90, 0x3C, 0x64), (0x90, 0x40, 0x7F)]),
    ([0xF4, 0x90, 0x3C, 0x40], [(0x90, 0x3C, 0x40)]),
    ([0xF0, 0x01, 0x02, 0x90, 0x3C, 0x40], [(0x90, 0x3C, 0x40)]),  # unterminated SysEx dropped
    ([0xE0, 0x00, 0x40], [(0xE0, 0x00, 0x40)]),
    ([0xC0, 0x05, 0x06], [(0xC0, 0x05), (0xC0, 0x06)]),  # running status with one data byte
    ([0x90, 0x3C, 0x40, 0xF2, 0x01, 0x02, 0x3D, 0x40], [(0x90, 0x3C, 0x40), (0xF2, 0x01, 0x02)]),
])
def test_stream_rules(stream: list[int], want: list[tuple[int, ...]]) -> None:
    assert tok(stream)[0] == want


def test_messages_split_across_chunks_and_counted_garbage() -> None:
    t = MidiTokenizer("t", warnings=WarningCounter("t", interval=3600))
    out = []
    for b in [0x12, 0x34, 0xB0, 0x07, 0xF8, 0x64, 0x08, 0x65]:  # two stray data bytes first
        out += [m for m, _ in t.feed(bytes([b]), 1.0)]
    assert out == [(0xF8,), (0xB0, 0x07, 0x64), (0xB0, 0x08, 0x65)]
    assert t.warnings.counts["garbage"] == 2


def test_sysex_is_capped_and_does_not_swallow_later_traffic() -> None:
    msgs, t = tok([0xF0] + [1] * 100 + [0xF7, 0xB0, 1, 2], cap=16)
    assert msgs == [(0xB0, 1, 2)]
    assert t.warnings.counts["sysex"] == 1
    msgs, _ = tok([0xF0] + [1] * 100 + [0xB0, 1, 2], cap=16)  # stuck F0 with no F7
    assert msgs == [(0xB0, 1, 2)]


# ------------------------------------------------------------------------------------ decoder
PROFILE = """
name = "test box"
channel = 1
[[control]]
name = "fader{n}"
count = 2
message = "cc"
number = 0
dead_band = 1
[[control]]
name = "enc{n}"
count = 3
message = "cc"
number = [10, 11, 12]
kind = "dial"
encoding = "twos_complement"
counts_per_turn = 10
[[control]]
name = "rel_off"
message = "cc"
number = 13
kind = "dial"
encoding = "offset64"
[[control]]
name = "rel_sm"
message = "cc"
number = 14
kind = "dial"
encoding = "sign_magnitude"
[[control]]
name = "pad{n}"
count = 4
message = "note"
number = 36
light = { on = 5, off = 0 }
[[control]]
name = "ccbutton"
message = "cc"
number = 40
kind = "button"
light = true
[[control]]
name = "wide"
message = "cc14"
number = 4
[[control]]
name = "wide_lf"
message = "cc14"
number = 5
order = "lsb_msb"
[[control]]
name = "bend"
message = "pitchbend"
lo = -1.0
[[control]]
name = "param"
message = "nrpn"
number = 300
[[control]]
name = "ring"
message = "cc"
number = 20
ring = { number = 30, lo = 1, hi = 11 }
"""


@pytest.fixture()
def dec() -> MidiDecoder:
    return MidiDecoder("midi://t", parse_profile(PROFILE, "test.toml"), WarningCounter("t", interval=3600))


def ev(dec: MidiDecoder, *msgs: tuple[int, ...]) -> list[ControlEvent]:
    out = []
    for m in msgs:
        out += dec.decode(m, 0.0)
    return out


def test_relative_encodings() -> None:
    assert [relative_delta(v, "twos_complement") for v in (1, 3, 127, 125, 63, 64)] == [1, 3, -1, -3, 63, -64]
    assert [relative_delta(v, "offset64") for v in (65, 63, 64, 70)] == [1, -1, 0, 6]
    assert [relative_delta(v, "sign_magnitude") for v in (1, 65, 5, 69)] == [1, -1, 5, -5]


def test_dials_in_each_encoding(dec: MidiDecoder) -> None:
    e = ev(dec, (0xB0, 10, 1), (0xB0, 10, 127), (0xB0, 11, 5), (0xB0, 13, 63), (0xB0, 14, 65), (0xB0, 13, 64))
    assert [(x.control, x.kind, x.delta) for x in e] == [
        ("enc1", "dial", 1.0), ("enc1", "dial", -1.0), ("enc2", "dial", 5.0), ("rel_off", "dial", -1.0),
        ("rel_sm", "dial", -1.0)]
    assert e[2].value == pytest.approx(0.5)  # 5 counts of 10 a turn
    big = ev(dec, (0xB0, 10, 63))  # an accelerated encoder: 63 counts, clamped to one turn
    assert big[0].value == 1.0


def test_notes_are_buttons_and_velocity_zero_releases(dec: MidiDecoder) -> None:
    e = ev(dec, (0x90, 36, 100), (0x90, 36, 0), (0x90, 37, 1), (0x80, 37, 64), (0x80, 38, 0))
    assert [(x.control, x.value) for x in e] == [("pad1", 1.0), ("pad1", 0.0), ("pad2", 1.0), ("pad2", 0.0)]
    assert ev(dec, (0xB0, 40, 127), (0xB0, 40, 127), (0xB0, 40, 0)) == ev(dec) + [
        ControlEvent("midi://t", "ccbutton", "button", 1.0, None, 127, 0.0),
        ControlEvent("midi://t", "ccbutton", "button", 0.0, None, 0, 0.0)]


def test_dead_band_stops_jitter_but_not_a_slow_move(dec: MidiDecoder) -> None:
    jitter = ev(dec, *[(0xB0, 0, v) for v in (116, 117, 116, 117, 116, 117)])
    assert len(jitter) <= 2  # the first value, perhaps one step; never the flicker
    dec.reset()
    slow = ev(dec, *[(0xB0, 1, v) for v in range(40, 60)])
    assert [x.raw for x in slow][-1] == 59 and len(slow) >= 18
    ends = ev(dec, (0xB0, 1, 127), (0xB0, 1, 126), (0xB0, 1, 127))
    assert ends[-1].value == 1.0  # the ends are always reachable


def test_14bit_pairs_in_both_orders(dec: MidiDecoder) -> None:
    e = ev(dec, (0xB0, 4, 0x40), (0xB0, 36, 0x10))  # MSB then LSB: one event, on the LSB
    assert [x.raw for x in e] == [0x40 << 7 | 0x10]
    assert ev(dec, (0xB0, 36, 0x11))[0].raw == 0x40 << 7 | 0x11  # LSB alone refines
    e = ev(dec, (0xB0, 37, 0x7F), (0xB0, 5, 0x20))  # LSB first: completed by the MSB
    assert [x.raw for x in e] == [0x20 << 7 | 0x7F]
    assert all(0.0 <= x.value <= 1.0 for x in e)


def test_pitch_bend_is_centred(dec: MidiDecoder) -> None:
    vals = [x.value for x in ev(dec, (0xE0, 0, 0), (0xE0, 0, 0x40), (0xE0, 0x7F, 0x7F))]
    assert vals == [-1.0, 0.0, 1.0]


def test_nrpn_data_entry(dec: MidiDecoder) -> None:
    e = ev(dec, (0xB0, 99, 2), (0xB0, 98, 44), (0xB0, 6, 0x7F), (0xB0, 38, 0x7F))
    assert [(x.control, x.value) for x in e] == [("param", 1.0)]
    assert ev(dec, (0xB0, 99, 1), (0xB0, 98, 0), (0xB0, 6, 3), (0xB0, 38, 3)) == []  # not in the profile


def test_unknown_messages_get_generic_names(dec: MidiDecoder) -> None:
    e = ev(dec, (0xB5, 7, 64), (0x93, 60, 10), (0xE2, 0, 0x40), (0xF8,), (0xC0, 3))
    assert [x.control for x in e] == ["ch6.cc7", "ch4.note60", "ch3.pitchbend"]
    assert len(ev(dec, (0xB5, 9, 1), (0xB5, 9, 1), (0xB5, 9, 1))) == 3  # maybe a relative encoder: every tick counts
    declared = {c.name for c in dec.controls()}
    assert {"ch6.cc7", "ch4.note60", "ch3.pitchbend", "fader1", "ring"} <= declared


# ------------------------------------------------------------------------------------ feedback
def test_lights_deduplicated_rate_limited_and_last_word_arrives() -> None:
    fb = Feedback(parse_profile(PROFILE, "test.toml"), WarningCounter("t", interval=3600), interval=0.02)
    assert not fb.request("fader1", 1.0)  # no light declared: nothing
    fb.request("pad1", 1.0)
    assert fb.due(0.0) == ([(0x90, 36, 5)], None)
    fb.request("pad1", 1.0)
    assert fb.due(0.001)[0] == []  # the same state again: not re-sent
    fb.request("ring", 0.0)
    fb.request("ring", 0.5)
    assert fb.due(0.002)[0] == [(0xB0, 30, 6)]  # only the newest level of a burst
    fb.request("ring", 1.0)
    msgs, nxt = fb.due(0.005)
    assert msgs == [] and nxt == pytest.approx(0.022)
    assert fb.due(0.03)[0] == [(0xB0, 30, 11)]
    fb.forget_sent()  # replugged: everything goes out again
    fb.request("pad1", 1.0)
    assert fb.due(1.0)[0] == [(0x90, 36, 5)]


def test_echo_of_our_own_lights_is_dropped() -> None:
    fb = Feedback(parse_profile(PROFILE, "test.toml"), WarningCounter("t", interval=3600))
    fb.request("ccbutton", 1.0)
    sent = fb.due(0.0)[0][0]
    assert fb.is_echo(sent, 0.001)
    assert not fb.is_echo(sent, 0.002)  # one echo per message sent
    assert not fb.is_echo((0xB0, 40, 0), 0.003)


# ------------------------------------------------------------------------------------ profiles
def test_shipped_profiles_load_and_are_recognised_by_port_name() -> None:
    names = profile_names()
    for want in ("nanokontrol2", "xtouch_mini", "bcr2000", "midimix", "apc_mini", "apc_mini_mk2",
                 "launch_control_xl", "mackie", "generic"):
        assert want in names
        load_profile(want)
    assert profile_for_port("nanoKONTROL2:nanoKONTROL2 _ CTRL 20:0") == "nanokontrol2"
    assert profile_for_port("X-TOUCH MINI:X-TOUCH MINI MIDI 1 24:0") == "xtouch_mini"
    assert profile_for_port("APC mini mk2:APC mini mk2 Control 28:0") == "apc_mini_mk2"
    assert profile_for_port("APC MINI:APC MINI MIDI 1 28:0") == "apc_mini"
    assert profile_for_port("Some Synth:Port 1") == "generic"


def test_channel_option_moves_the_default_channel() -> None:
    p = load_profile("launch_control_xl", channel=3)
    assert {c.channel for c in p.controls} == {2}
    assert load_profile("mackie", channel=5).control("fader3").channel == 2  # explicit channels stay


def test_profile_errors_name_the_file_and_line(tmp_path: Path) -> None:
    bad = PROFILE.replace('encoding = "offset64"', 'encoding = "offset63"')
    with pytest.raises(ProfileError, match=r"^bad\.toml:\d+: expected one of twos_complement"):
        parse_profile(bad, "bad.toml")
    line = int(str(pytest.raises(ProfileError, parse_profile, bad, "bad.toml").value).split(":")[1])
    assert 'offset63' in bad.splitlines()[line - 1]
    with pytest.raises(ProfileError, match="missing.toml: MIDI profile file not found"):
        load_profile(str(tmp_path / "missing.toml"))
    with pytest.raises(ProfileError, match="unknown MIDI profile 'nanokontrol3'"):
        load_profile("nanokontrol3")


def test_damaged_profiles_give_a_profile_or_one_line() -> None:
    rng = random.Random(12)
    texts = [(Path(__file__).parents[2] / "devices" / "midi" / "profiles" / f"{n}.toml").read_text()
             for n in profile_names()] + [PROFILE]
    for k in range(400):
        text = rng.choice(texts)
        chars = list(text)
        for _ in range(rng.randint(1, 6)):
            op, i = rng.random(), rng.randrange(len(chars) + 1)
            if op < 0.4 and i < len(chars):
                del chars[i]
            elif op < 0.8:
                chars.insert(i, rng.choice('=[]{}"\n0123456789-.,abc# '))
            else:
                chars[i:i + 8] = []
        try:
            prof = parse_profile("".join(chars), f"damaged{k}.toml")
        except ProfileError as err:
            msg = str(err)
            assert "\n" not in msg and msg.startswith(f"damaged{k}.toml:"), msg
            continue
        for cd in prof.controls:
            assert 0 <= cd.channel <= 15 and cd.kind in ("axis", "dial", "button") and cd.lo < cd.hi


# ------------------------------------------------------------------------------------ fuzzing
FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
channel_msgs = st.builds(lambda s, a, b: (s, a, b)[: 1 + message_length(s)],
                         st.integers(0x80, 0xEF), st.integers(0, 127), st.integers(0, 127))


def well_formed(m: tuple[int, ...]) -> bool:
    if m[0] == 0xF0:
        return m[-1] == 0xF7 and all(b < 0x80 for b in m[1:-1])
    return m[0] >= 0x80 and len(m) == 1 + message_length(m[0]) and all(b < 0x80 for b in m[1:])


@FUZZ
@given(st.binary(max_size=400), st.lists(st.integers(0, 400), max_size=8))
def test_tokenizer_random_bytes_any_chunking(data: bytes, cuts: list[int]) -> None:
    whole, _ = tok(data, cap=64)
    t = MidiTokenizer("f", sysex_cap=64, warnings=WarningCounter("f", interval=3600))
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    pieces = [m for a, b in zip(points, points[1:]) for m, _ in t.feed(data[a:b], 0.0)]
    assert pieces == whole  # chunking never changes the result
    assert all(well_formed(m) for m in whole)


@FUZZ
@given(st.lists(channel_msgs, min_size=1, max_size=30), st.lists(st.tuples(st.integers(0, 999), st.sampled_from(sorted(REALTIME))), max_size=10),
       st.booleans())
def test_realtime_bytes_anywhere_change_nothing(msgs: list[tuple[int, ...]], inserts: list[tuple[int, int]],
                                                running: bool) -> None:
    stream = bytearray()
    last = 0
    for m in msgs:
        stream += bytes(m[1:]) if running and m[0] == last and m[0] < 0xF0 else bytes(m)
        last = m[0]
    for pos, rt in sorted(inserts, reverse=True):
        stream.insert(pos % (len(stream) + 1), rt)
    got, t = tok(bytes(stream))
    assert [m for m in got if m[0] < 0xF8] == msgs
    assert len([m for m in got if m[0] >= 0xF8]) == len(inserts)
    assert t.warnings.total() == 0


@FUZZ
@given(st.sampled_from([*profile_names(), "test"]),
       st.lists(st.tuples(st.integers(0x80, 0xEF), st.sampled_from([0, 1, 4, 5, 6, 10, 13, 14, 20, 36, 37, 38, 96, 97, 98, 99, 100, 101]) | st.integers(0, 127),
                          st.integers(0, 127)), max_size=60))
def test_every_profile_decodes_any_message_inside_its_ranges(name: str, msgs: list[tuple[int, int, int]]) -> None:
    """Every shipped profile, and the test profile with 14-bit pairs, NRPN and every encoding."""
    prof = parse_profile(PROFILE, "test.toml") if name == "test" else load_profile(name)
    d = MidiDecoder("f", prof, WarningCounter("f", interval=3600))
    declared = {c.name: c for c in d.controls()}
    for m in msgs:
        for e in d.decode(m[: 1 + message_length(m[0])], 0.0):
            info = declared[e.control]
            assert e.kind == info.kind and info.lo <= e.value <= info.hi, (e, info)
            if e.kind == "button":
                assert e.value in (0.0, 1.0)


def test_port_names_match_by_substring_without_alsa_numbers() -> None:
    from devices.midi.port import clean_name, find_port

    alsa = ["Midi Through:Midi Through Port-0 14:0", "nanoKONTROL2:nanoKONTROL2 _ CTRL 20:0",
            "APC mini mk2:APC mini mk2 Notes 24:1", "APC mini mk2:APC mini mk2 Control 24:0"]
    assert clean_name(alsa[1]) == "nanoKONTROL2:nanoKONTROL2 _ CTRL"
    assert find_port(alsa, "NANOkontrol2") == 1
    assert find_port(alsa, "20:0") is None  # the numbers change on replug: never matched
    assert find_port(alsa, "apc mini mk2", prefer="control") == 3  # LEDs answer on the Control port
    assert find_port(alsa, "launch control") is None


def test_the_example_profile_loads_and_decodes() -> None:
    path = Path(__file__).parents[2] / "examples" / "midi" / "my_controller.toml"
    prof = load_profile(str(path))
    d = MidiDecoder("x", prof, WarningCounter("x", interval=3600))
    e = ev(d, (0xB0, 16, 127), (0xB0, 40, 0x7F), (0xB0, 8, 0x40), (0x99, 36, 9), (0xE0, 0, 0x40))
    assert [(x.control, x.kind) for x in e] == [("encoder1", "dial"), ("fine", "axis"), ("pad1", "button"),
                                                ("wheel", "axis")]
    assert e[0].delta == -1 and e[1].raw == 0x40 << 7 | 0x7F and e[3].value == 0.0
    assert prof.control("encoder1").ring.ring_value(1.0) == (0xB0, 48, 15)


def test_rpn_increment_and_the_null_rpn() -> None:
    text = ('name = "r"\n[[control]]\nname = "bend_range"\nmessage = "rpn"\nnumber = 0\norder = "msb"\n'
            '[[control]]\nname = "tune"\nmessage = "nrpn"\nnumber = 5\nkind = "dial"\nencoding = "offset64"\n')
    d = MidiDecoder("r", parse_profile(text, "r.toml"), WarningCounter("r", interval=3600))
    e = ev(d, (0xB0, 101, 0), (0xB0, 100, 0), (0xB0, 6, 12), (0xB0, 96, 0), (0xB0, 97, 0), (0xB0, 97, 0))
    assert [x.raw for x in e] == [12, 13, 12, 11]  # data entry, then increment/decrement steps
    assert ev(d, (0xB0, 101, 127), (0xB0, 100, 127), (0xB0, 6, 50)) == []  # the null RPN selects nothing
    e = ev(d, (0xB0, 99, 0), (0xB0, 98, 5), (0xB0, 6, 66), (0xB0, 96, 0))
    assert [(x.control, x.delta) for x in e] == [("tune", 2.0), ("tune", 1.0)]  # a relative NRPN encoder


def test_a_unix_socket_file_is_a_server_only_while_someone_listens(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A JACK server killed leaves its socket file: the file alone is no server. Listed as listening
    in /proc/net/unix it is; unlisted (another network namespace sharing /dev/shm), a connection
    decides: taken, a server; refused, a left-over file."""
    import socket

    from devices.midi import port

    live, stale = tmp_path / "live.sock", tmp_path / "stale.sock"
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(live))
    server.listen(1)
    gone = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    gone.bind(str(stale))
    gone.close()  # as a killed server leaves it: the file, nobody behind it
    try:
        assert port.unix_socket_listened(str(live)) and not port.unix_socket_listened(str(stale))
        empty = tmp_path / "unix"
        empty.write_text("Num       RefCount Protocol Flags    Type St Inode Path\n")
        monkeypatch.setattr(port, "PROC_NET_UNIX", str(empty))  # another namespace: nothing listed
        assert port.unix_socket_listened(str(live)) and not port.unix_socket_listened(str(stale))
        assert not port.unix_socket_listened(str(tmp_path / "none.sock"))
    finally:
        server.close()
