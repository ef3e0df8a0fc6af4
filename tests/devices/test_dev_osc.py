"""osc:// end to end over real UDP sockets on 127.0.0.1: every profile, garbage, oversized and
future-dated bundles, address patterns, floods, the bind address and the sender allow-list."""

from __future__ import annotations

import os
import random
import socket
import struct
import threading
import time

import pytest
from netdev import listening, osc_bundle, osc_message

import devices
from devices.osc import MAX_DEPTH, PROFILES, OscDevice, decode_packet
from devices.spec import parse_spec
from devices.udp import exposure_text, parse_allow, sender_allowed


def values(events: list, control: str) -> list[float]:
    return [e.value for e in events if e.control == control]


def test_generic_addresses_become_controls_named_by_address() -> None:
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(osc_message("/face/channel/zygomaticus_major_l", 0.8), osc_message("/face/au/12", 0.5),
                 osc_message("/face/expression/happiness", 1), osc_message("/face/channel/age", 40.0))
        got = lis.control_events("/face/channel/age")
    by = {e.control: e for e in got}
    assert by["/face/channel/zygomaticus_major_l"].value == pytest.approx(0.8)
    assert by["/face/au/12"].value == pytest.approx(0.5) and by["/face/au/12"].kind == "axis"
    assert by["/face/expression/happiness"].value == 1.0  # an int argument works like a float
    assert by["/face/channel/age"].value == 40.0  # generic values pass in the sender's units
    assert all(e.device == "osc://127.0.0.1:0" and e.t > 0 for e in got)


def test_multi_argument_messages_and_booleans() -> None:
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(osc_message("/pad", 0.25, 0.75), osc_message("/go", True), osc_message("/go", True),
                 osc_message("/go", False), osc_message("/label", "text only"), osc_message("/end", 1.0))
        got = lis.control_events("/end")
    assert values(got, "/pad:0") == [0.25] and values(got, "/pad:1") == [0.75]
    assert [(e.kind, e.value) for e in got if e.control == "/go"] == [("button", 1.0), ("button", 0.0)]
    assert not [e for e in got if e.control.startswith("/label")]


def test_touchosc_simple_layout() -> None:
    with listening("osc://127.0.0.1:0?profile=touchosc") as lis:
        dev = lis.dev
        assert dev.control("/1/fader1").kind == "axis" and dev.control("/2/push16").kind == "button"
        lis.send(osc_message("/1"),  # a page change carries no value
                 osc_message("/1/fader1", 0.5), osc_message("/1/fader2", 1.3),
                 osc_message("/2/push3", 1.0), osc_message("/2/push3", 1.0), osc_message("/2/push3", 0.0),
                 osc_message("/1/toggle2", 1.0), osc_message("/3/xy", 0.1, 0.9),
                 osc_message("/4/multitoggle/3/5", 1.0), osc_message("/1/fader1/z", 1.0),
                 osc_message("/mine/push9", 127.0), osc_message("/end", 0.0))
        got = lis.control_events("/end")
        assert dev.warnings.counts["range"] == 1
    assert values(got, "/1/fader1") == [0.5]
    assert values(got, "/1/fader2") == [1.0]  # clamped to the declared range, counted
    assert [(e.kind, e.value) for e in got if e.control == "/2/push3"] == [("button", 1.0), ("button", 0.0)]
    assert values(got, "/1/toggle2") == [1.0]
    assert values(got, "/3/xy:0") == [pytest.approx(0.1)] and values(got, "/3/xy:1") == [pytest.approx(0.9)]
    assert values(got, "/4/multitoggle/3/5") == [1.0] and values(got, "/1/fader1/z") == [1.0]
    assert [e.kind for e in got if e.control == "/mine/push9"] == ["button"]  # any layout's pushes
    assert not [e for e in got if e.control == "/1"]


def test_openstage_widgets_and_momentary_taps() -> None:
    with listening("osc://127.0.0.1:0?profile=openstage") as lis:
        lis.send(osc_message("/fader_1", 0.3), osc_message("/knob_2", 0.6), osc_message("/button_4", 1.0),
                 osc_message("/button_4", 0.0), osc_message("/button_5"),  # momentary: no value, a tap
                 osc_message("/xy_1", 0.2, 0.4), osc_message("/end", 0.0))
        got = lis.control_events("/end")
    assert values(got, "/fader_1") == [pytest.approx(0.3)] and values(got, "/knob_2") == [pytest.approx(0.6)]
    assert values(got, "/button_4") == [1.0, 0.0]
    assert values(got, "/button_5") == [1.0, 0.0]
    assert values(got, "/xy_1:0") == [pytest.approx(0.2)]


def test_unknown_profile_and_option_show_the_form() -> None:
    with pytest.raises(devices.DeviceSpecError, match="touchosc"):
        devices.open_device("osc://127.0.0.1:0?profile=lemur")
    with pytest.raises(devices.DeviceSpecError, match="osc://127.0.0.1:9000"):
        devices.open_device("osc://127.0.0.1:0?prfile=touchosc")


def test_garbage_never_stops_the_reader() -> None:
    rng = random.Random(12)
    junk = [b"", b"hello world", bytes(rng.randrange(256) for _ in range(200)), b"/addr\x00\x00\x00,fff\x00\x00",
            b"#bundle\x00" + b"\x00" * 8 + struct.pack(">i", 4000) + b"/x\x00\x00",  # element overruns
            b"#bundle\x00" + b"\x00" * 8 + struct.pack(">i", -8), b"\x80" * 64, osc_message("/ok", 1.0)[:-2]]
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(*junk, osc_message("/after", 0.5))
        got = lis.control_events("/after")
        assert values(got, "/after") == [0.5]
        assert lis.dev.warnings.counts["garbage"] >= len(junk) - 1  # the empty datagram may not count
        assert lis.dev.connected


def test_oversized_datagrams_are_dropped_and_counted() -> None:
    big = osc_message("/big", b"\x00" * 40000)  # a blob: 40 kB, above the default 32 kB limit
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(big, osc_message("/after", 1.0))
        got = lis.control_events("/after")
        assert lis.dev.warnings.counts["oversized"] == 1 and values(got, "/after") == [1.0]
    with listening("osc://127.0.0.1:0?max_size=128") as lis:
        lis.send(osc_bundle([osc_message(f"/w{i}", 0.5) for i in range(20)]), osc_message("/after", 1.0))
        got = lis.control_events("/after")
        assert lis.dev.warnings.counts["oversized"] == 1 and [e.control for e in got] == ["/after"]


def test_future_time_tags_never_delay_dispatch() -> None:
    """python-osc's own server would sleep its thread until the tag (an hour here)."""
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(osc_bundle([osc_message("/later", 0.7)], timetag=time.time() + 3600), osc_message("/now", 0.1))
        got = lis.control_events("/now")
        assert values(got, "/later") == [pytest.approx(0.7)] and values(got, "/now") == [pytest.approx(0.1)]
        assert [e.control for e in got] == ["/later", "/now"]  # arrival order, not time-tag order
        assert lis.dev.parser.future_bundles == 1


def test_nested_bundles_are_flattened_and_bounded() -> None:
    inner = osc_bundle([osc_message("/a", 0.1), osc_message("/b", 0.2)])
    from pythonosc.osc_bundle import OscBundle
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder

    outer = OscBundleBuilder(IMMEDIATELY)
    outer.add_content(OscBundle(inner))
    msgs = decode_packet(outer.build().dgram)
    assert [(m.address, m.args) for m in msgs] == [("/a", (pytest.approx(0.1),)), ("/b", (pytest.approx(0.2),))]
    deep = osc_message("/deep", 1.0)
    for _ in range(MAX_DEPTH + 1):
        deep = b"#bundle\x00" + struct.pack(">Q", 1) + struct.pack(">i", len(deep)) + deep
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(deep, osc_bundle([osc_message("/m", float(i)) for i in range(1500)]), osc_message("/after", 1.0))
        got = lis.control_events("/after")
        assert [e.control for e in got] == ["/after"]
        assert lis.dev.warnings.counts["garbage"] == 2


def test_address_patterns_are_refused_not_fanned_out() -> None:
    with listening("osc://127.0.0.1:0?profile=touchosc") as lis:
        lis.send(osc_message("/1/*", 1.0), osc_message("/{1,2}/fader1", 1.0), osc_message("/after", 1.0))
        got = lis.control_events("/after")
        assert [e.control for e in got] == ["/after"] and lis.dev.warnings.counts["pattern"] == 2


def test_nothing_is_ever_sent_back() -> None:
    with listening("osc://127.0.0.1:0") as lis:
        lis.send(osc_message("/ping", 1.0), osc_message("/info"), osc_message("/after", 1.0))
        lis.control_events("/after")
        lis.sock.settimeout(0.3)
        with pytest.raises(socket.timeout):
            lis.sock.recvfrom(65536)


def test_a_flood_is_bounded_and_the_reader_stays_live() -> None:
    """Far more datagrams than max_rate: the excess is dropped and counted, axis values of a
    batch are coalesced, and a message after the flood still arrives."""
    with listening("osc://127.0.0.1:0?max_rate=2000") as lis:
        flood = osc_message("/face/channel/jaw", 0.5)
        stop = threading.Event()
        sent = [0]

        def blast() -> None:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            while not stop.is_set() and sent[0] < 200_000:
                try:
                    s.sendto(flood, ("127.0.0.1", lis.port))
                    sent[0] += 1
                except OSError:
                    pass
            s.close()

        th = threading.Thread(target=blast)
        th.start()
        assert lis.wait_for(lambda: lis.dev.warnings.counts["flood"] > 0)
        stop.set()
        th.join()
        got: list = []
        after = 0
        for _ in range(100):  # the kernel drops what does not fit its buffer: send until it fits
            lis.send(osc_message("/after", 1.0))
            after += 1
            got += lis.events(lambda es: any(e.control == "/after" for e in es), timeout=0.05)
            if values(got, "/after"):
                break
        assert values(got, "/after")[:1] == [1.0]
        assert len(got) < sent[0] and lis.dev.datagrams < sent[0] + after  # the probes count too


def test_binds_localhost_by_default() -> None:
    with listening("osc://:0") as lis:
        assert lis.dev.bound[0] == "127.0.0.1"
    with listening("osc://[::1]:0") as lis:  # IPv6 loopback
        assert lis.dev.bound[0] == "::1"
    with listening("osc://localhost:0") as lis:
        assert lis.dev.bound[0] == "127.0.0.1"
    assert OscDevice(parse_spec("osc://")).port == 9000  # the default port (not opened here)


@pytest.mark.parametrize("spec", ["osc://0.0.0.0:9000", "osc://192.168.1.5:9000", "osc://[::]:9000"])
def test_listening_beyond_localhost_must_be_asked_for(spec: str) -> None:
    with pytest.raises(devices.DeviceSpecError, match="lan=1") as err:
        devices.open_device(spec)
    # the spec the message suggests is one to type (it said osc://:::9000?lan=1 for [::])
    suggested = str(err.value).split("(", 1)[1].split(",", 1)[0]
    assert suggested == spec + "?lan=1"
    devices.parse_spec(suggested)


def test_lan_option_prints_what_it_exposes(capsys: pytest.CaptureFixture[str]) -> None:
    dev = OscDevice(parse_spec("osc://0.0.0.0:0?lan=1&allow=10.1.2.3,192.168.7.0/24"))
    try:
        assert "every network interface" in dev.exposure and "10.1.2.3, 192.168.7.0/24" in dev.exposure
        dev.host = "127.0.0.1"  # the tests never listen beyond loopback: open on it, print as for the LAN
        dev.open()
        err = capsys.readouterr().err
        assert f"listening for OSC on UDP port {dev.bound[1]} of every network interface" in err
        assert "only datagrams from 10.1.2.3, 192.168.7.0/24 are used" in err
    finally:
        dev.close()
    open_all = exposure_text("osc://0.0.0.0:9000?lan=1", "OSC", "0.0.0.0", 9000, ())
    assert "any machine" in open_all and "allow=" in open_all


def test_port_0_says_the_port_it_bound_and_keeps_it(capsys: pytest.CaptureFixture[str]) -> None:
    """Port 0 lets the system pick a free port; the sender must be told which. It was named nowhere
    (the description said udp 127.0.0.1:0, nothing was printed), and a reopen would pick another."""
    dev = OscDevice(parse_spec("osc://127.0.0.1:0"))
    try:
        dev.open()
        port = dev.bound[1]
        err = capsys.readouterr().err
        assert err == f"osc://127.0.0.1:0: listening for OSC on UDP port {port} of 127.0.0.1\n"
        assert dev.description.endswith(f"udp 127.0.0.1:{port}")
        dev._close_handle()  # as when the socket is lost: the reconnect reopens on the told port
        dev._open()
        assert dev.bound[1] == port and capsys.readouterr().err == ""
    finally:
        dev.close()


def test_sender_allow_list() -> None:
    with listening("osc://127.0.0.1:0?allow=10.9.8.7") as lis:  # not us: everything is refused
        lis.send(osc_message("/x", 1.0))
        assert lis.wait_for(lambda: lis.dev.refused == 1)
        assert lis.q.get(timeout=0.2) is not None  # connected
        assert lis.q.get(timeout=0.2) is None and lis.dev.datagrams == 0
    with listening("osc://127.0.0.1:0?allow=127.0.0.1") as lis:
        lis.send(osc_message("/x", 1.0))
        assert values(lis.control_events("/x"), "/x") == [1.0]
    nets = parse_allow("192.168.1.20,10.0.0.0/8,fe80::1", "s")
    assert sender_allowed("192.168.1.20", nets) and sender_allowed("10.4.5.6", nets)
    assert sender_allowed("::ffff:10.1.1.1", nets) and sender_allowed("fe80::1", nets)
    assert not sender_allowed("192.168.1.21", nets) and not sender_allowed("junk", nets)
    assert sender_allowed("8.8.8.8", ())
    with pytest.raises(devices.DeviceSpecError, match="allow"):
        parse_allow("192.168.1.300", "s")


def test_button_addresses_are_bounded() -> None:
    from devices.osc import MAX_BUTTONS, OscParser

    p = OscParser("osc://t", PROFILES["generic"])
    for i in range(MAX_BUTTONS + 10):
        p.message(f"/b{i}", (True,), 0.0, [])
    assert len(p._down) == MAX_BUTTONS and p.warnings.counts["range"] == 10


def test_port_in_use_is_one_clear_error() -> None:
    with listening("osc://127.0.0.1:0") as lis:
        with pytest.raises(devices.DeviceError, match="in use"):
            devices.open_device(f"osc://127.0.0.1:{lis.port}")


def test_close_is_prompt_and_idempotent() -> None:
    with listening("osc://127.0.0.1:0") as lis:
        fds = len(os.listdir("/proc/self/fd"))
        lis.dev.close()
        lis.dev.close()
        assert not lis.dev.connected and not lis.dev._thread.is_alive()
        assert len(os.listdir("/proc/self/fd")) < fds  # socket and wake pipe released


def test_a_comma_among_the_type_tags_is_refused_quietly(caplog: pytest.LogCaptureFixture) -> None:
    """A datagram typed ',,f' (a sender's bug): python-osc logged 'Unhandled parameter type: ,' on
    the root logger for every one, so a sender at 100 Hz printed 100 unthrottled lines a second on
    the show's terminal. It is garbage now, counted by the device's own throttled warnings."""
    bad = b"/face/jaw\x00\x00\x00,,f\x00" + struct.pack(">f", 0.5)
    with pytest.raises(Exception, match="unknown argument types"):
        decode_packet(bad)
    with caplog.at_level("WARNING"), listening("osc://127.0.0.1:0") as lis:
        lis.send(*[bad] * 20, osc_message("/after", 0.5))
        assert values(lis.control_events("/after"), "/after") == [0.5]
        assert lis.dev.warnings.counts["garbage"] == 20
    assert not [r for r in caplog.records if r.name == "root"]


def test_a_damaged_message_is_named_in_a_short_line() -> None:
    """Type tags ',[[[...' (3000 unclosed arrays): python-osc's error quoted the whole tag string, so
    the show's warning line ran to 3000+ characters. The reason is cut to a readable length."""
    tags = b"," + b"[" * 3000 + b"\x00"
    data = b"/a\x00\x00" + tags + b"\x00" * (-len(tags) % 4)
    with pytest.raises(Exception) as err:
        decode_packet(data)
    assert "damaged message" in str(err.value) and len(str(err.value)) < 200


def test_lan_on_the_loopback_is_refused_and_no_address_means_every_interface() -> None:
    """README said 'add lan=1 to listen beyond this machine' beside `osc://127.0.0.1:9000`: that spec
    with lan=1 still listened on the loopback alone, and the phone never reached it, without a word.
    Now lan=1 on a loopback address is one line naming the spec that listens on the LAN, and lan=1
    with no address named listens on every interface (as panel:// does)."""
    for spec in ("osc://127.0.0.1:9000?lan=1", "osc://localhost:9000?lan=1", "osc://[::1]:9000?lan=1"):
        with pytest.raises(devices.DeviceSpecError, match="this machine alone") as err:
            OscDevice(parse_spec(spec))
        assert "osc://0.0.0.0:9000?lan=1" in str(err.value)
    dev = OscDevice(parse_spec("osc://:9000?lan=1&allow=10.1.2.3"))
    assert dev.host == "0.0.0.0" and "every network interface" in dev.exposure
