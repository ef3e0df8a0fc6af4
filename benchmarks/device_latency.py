"""Device latency and parser throughput.

1. Latency: a box emulator, in a separate process like real hardware, writes a report into a
   pseudo-terminal; we time from the write of the report's last byte to the moment the event
   reaches a listener of a started device (pyserial read in select, parse, dispatch). The bytes are paced at the line's byte time (the pty itself has no
   baud rate), so on real hardware add the wire time of one report to these numbers: 3 bytes at
   9600 baud ~ 3.1 ms for the SGI box, a 6-byte line at 115200 baud ~ 0.5 ms for the text protocol.
2. Throughput: each parser alone, fed a long valid byte stream in 4 KiB chunks.
3. Network listeners (OSC, face-tracking streams): a sender process sends UDP datagrams to
   127.0.0.1; we time from just before its sendto to the event at a listener, beside the
   transport's own floor (a plain socket read by a blocking thread), and each parser's throughput.

3. MIDI: rawmidi:// over the same pty at 31250 baud (DIN MIDI), and midi:// through a private dummy
   JACK server (started and stopped here) from a controller in its own process; JACK hands MIDI
   over once per period, so its latency is shown next to the period.

Run:  .venv/bin/python benchmarks/device_latency.py [--events N] [--json] [--jack-periods 64,256]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "devices")]  # the pty box emulators live with the tests

from emulators import SgiBoxEmulator, TextBoxEmulator  # noqa: E402

from devices import ControlEvent, open_device  # noqa: E402


def percentile(values: list[float], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(p / 100 * (len(ordered) - 1))))]


def box_process(kind: str, link: str, conn: Any) -> None:
    """The box, in its own process as real hardware would be: it must not share our GIL."""
    emu: Any = SgiBoxEmulator(Path(link)) if kind == "sgi" else TextBoxEmulator(Path(link))
    conn.send("ready")
    while (i := conn.recv()) is not None:
        if kind == "rawmidi":  # a CC of a DIN MIDI box at 31250 baud, running status every other one
            msg = bytes([0xB0, i % 8, i % 128]) if i % 2 == 0 else bytes([i % 8, i % 128])
            t = paced_write(emu.port.write, msg, 10 / 31250)
        elif kind == "sgi":
            t = paced_write(emu.port.write, emu.dial_packet(i % 8, 1 if i % 2 else -1), 10 / 9600)
        else:
            t = paced_write(emu.port.write, f"D{i % 8} {'+1' if i % 2 else '-1'}\n".encode(), 10 / 115200)
        conn.send(t)
    emu.port.close()


def paced_write(write: Callable[[bytes], None], data: bytes, byte_time: float) -> float:
    """Write like a serial line: one byte per ``byte_time``; returns the time of the last byte."""
    t = 0.0
    for i in range(len(data)):
        if i:
            time.sleep(byte_time)
        t = time.monotonic()
        write(data[i : i + 1])
    return t


def latency(kind: str, spec_template: str, n: int, tmp: Path, warmup: int = 20) -> dict[str, float]:
    """Latency over ``n`` reports; CLOCK_MONOTONIC is system-wide, so the box's write time and
    our arrival time compare directly across the two processes."""
    link = tmp / kind
    parent, child = multiprocessing.get_context("fork").Pipe()
    proc = multiprocessing.get_context("fork").Process(target=box_process, args=(kind, str(link), child))
    proc.start()  # forked before any device thread exists
    assert parent.recv() == "ready"
    arrived = threading.Event()
    stamp: list[float] = []

    def listener(event: Any) -> None:
        if isinstance(event, ControlEvent):
            stamp.append(time.monotonic())
            arrived.set()

    dev = open_device(spec_template.format(link=link))
    dev.add_listener(listener)
    dev.start()
    lat: list[float] = []
    try:
        for i in range(n + warmup):
            arrived.clear()
            stamp.clear()
            parent.send(i)
            # wait for the event first: reading the box's timestamp now would wake this thread
            # just as the reader needs the GIL, and measure our own contention
            if not arrived.wait(2.0):
                raise RuntimeError(f"{kind}: event {i} never arrived")
            t_write = parent.recv()
            if i >= warmup:
                lat.append((stamp[0] - t_write) * 1000)
            time.sleep(0.002)
    finally:
        dev.close()
        parent.send(None)
        proc.join(5)
    return {"n": len(lat), "p50_ms": statistics.median(lat), "p99_ms": percentile(lat, 99), "max_ms": max(lat)}


def sgi_latency(n: int, tmp: Path) -> dict[str, float]:
    result = latency("sgi", "sgi://{link}", n, tmp)
    result["wire_ms"] = 3 * 10 / 9600 * 1000
    return result


def text_latency(n: int, tmp: Path) -> dict[str, float]:
    result = latency("text", "serial://{link}?baud=115200", n, tmp)
    result["wire_ms"] = 6 * 10 / 115200 * 1000
    return result


def rawmidi_latency(n: int, tmp: Path) -> dict[str, float]:
    result = latency("rawmidi", "rawmidi://{link}?baud=31250&profile=nanokontrol2", n, tmp)
    result["wire_ms"] = 3 * 10 / 31250 * 1000
    return result


def midi_box_process(server: str, conn: Any) -> None:
    """A MIDI controller on the JACK server, in its own process: one CC per request."""
    import os

    os.environ["JACK_DEFAULT_SERVER"] = server
    os.environ["JACK_NO_START_SERVER"] = "1"
    import rtmidi

    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="benchbox")
    out.open_virtual_port("_MIDI 1")
    conn.send("ready")
    while (i := conn.recv()) is not None:
        t = time.monotonic()
        out.send_message([0xB0, i % 8, i % 128])
        conn.send(t)
    out.close_port()
    out.delete()


def midi_jack_latency(n: int, period: int) -> dict[str, float]:
    """JACK port -> event at a listener of a started midi:// device, on a private dummy JACK
    server at ``period`` frames (48 kHz); JACK delivers MIDI once per period, printed beside."""
    import os
    import subprocess

    server = f"fpbench{os.getpid()}"
    jackd = subprocess.Popen(["jackd", "-n", server, "--no-realtime", "-d", "dummy", "-r", "48000", "-p", str(period)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    old = {k: os.environ.get(k) for k in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}
    try:
        deadline = time.monotonic() + 15
        while subprocess.run(["jack_lsp", "-s", server], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             env={**os.environ, "JACK_NO_START_SERVER": "1"}).returncode != 0:
            if time.monotonic() > deadline:
                raise RuntimeError("jackd did not start")
            time.sleep(0.05)
        os.environ["JACK_DEFAULT_SERVER"], os.environ["JACK_NO_START_SERVER"] = server, "1"
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=midi_box_process, args=(server, child))
        proc.start()
        assert parent.recv() == "ready"
        result = _timed_events(open_device("midi://benchbox?api=jack&profile=nanokontrol2"), parent, n, "midi")
        bare = _timed_events(_BareRtmidi("benchbox:_MIDI 1"), parent, n, "midi")
        result.update({"bare_p50_ms": bare["p50_ms"], "bare_p99_ms": bare["p99_ms"]})
        parent.send(None)
        proc.join(5)
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        jackd.terminate()
        jackd.wait(10)
    result["period_ms"] = period / 48000 * 1000
    return result


class _BareRtmidi:
    """The transport alone: a python-rtmidi input whose callback is the listener (no device layer,
    no reader thread, no decoding), as the reference the device's figures are compared with."""

    def __init__(self, port: str) -> None:
        import rtmidi

        self.port = port
        self.inp = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, name="fpbare")
        self.listeners: list[Any] = []

    def add_listener(self, fn: Any) -> None:
        self.listeners.append(fn)

    def start(self) -> None:
        self.inp.open_port(self.inp.get_ports().index(self.port))
        self.inp.set_callback(lambda item, data=None: [fn(ControlEvent("bare", "x", "axis", 0.0)) for fn in self.listeners])

    def close(self) -> None:
        self.inp.close_port()
        self.inp.delete()


def _timed_events(dev: Any, parent: Any, n: int, kind: str, warmup: int = 20) -> dict[str, float]:
    """Ask the box process for one message at a time; latency = our arrival - its send time.
    A message JACK drops (an XRun of the dummy driver) is counted, not waited for forever."""
    arrived = threading.Event()
    stamp: list[float] = []

    def listener(event: Any) -> None:
        if isinstance(event, ControlEvent):
            stamp.append(time.monotonic())
            arrived.set()

    dev.add_listener(listener)
    dev.start()
    lat: list[float] = []
    lost = 0
    try:
        for i in range(n + warmup):
            arrived.clear()
            stamp.clear()
            parent.send(i)
            ok = arrived.wait(1.0)
            t_send = parent.recv()
            if not ok:
                lost += 1
                continue
            if i >= warmup:
                lat.append((stamp[0] - t_send) * 1000)
            time.sleep(0.002)
    finally:
        dev.close()
    return {"n": len(lat), "lost": lost, "p50_ms": statistics.median(lat), "p99_ms": percentile(lat, 99),
            "max_ms": max(lat)}


def throughput() -> dict[str, dict[str, float]]:
    from devices.controlsets import sgi_controls  # noqa: F401  (import cost outside the timing)
    from devices.firmata import FirmataParser
    from devices.hid.descriptor import GenericDecoder, ReportDescriptor
    from devices.sgi import SgiParser, button_code
    from devices.textserial import TextParser

    sys.path.insert(0, str(ROOT / "tests" / "devices"))
    from devdata import MAPLE_RDESC, MAPLE_REPORT

    def run(name: str, feed: Callable[[bytes, float], list[Any]], unit: bytes, events_per_unit: int) -> dict[str, float]:
        stream = unit * max(1, (1 << 20) // len(unit))
        t0 = time.perf_counter()
        count = 0
        for i in range(0, len(stream), 4096):
            count += len(feed(stream[i : i + 4096], 0.0))
        dt = time.perf_counter() - t0
        return {"events_per_s": count / dt, "MB_per_s": len(stream) / dt / 1e6}

    sgi_unit = bytes([0x30, 0x00, 0x05, 0x30, 0x00, 0x00, button_code(3, True), button_code(3, False)])
    firmata_unit = bytes([0xE0, 0x10, 0x01, 0xE0, 0x11, 0x01, 0x90, 0x7B, 0x01, 0x90, 0x7F, 0x01])
    out = {
        "sgi": run("sgi", SgiParser("b").feed, sgi_unit, 4),
        "text": run("text", TextParser("b").feed, b"D0 +5\nB3 1\nA1 0.731\nB3 0\n", 4),
        "firmata": run("firmata", FirmataParser("b", [0, 1], [2, 3]).feed, firmata_unit, 4),
    }
    from devices.midi.decoder import MidiDecoder
    from devices.midi.profile import load_profile
    from devices.midi.tokenizer import MidiTokenizer

    midi_unit = bytes([0xB0, 0x00, 0x10, 0x00, 0x11, 0xF8, 0x10, 0x40, 0x90, 0x24, 0x7F, 0x24, 0x00])  # 5 messages
    out["midi-tokenizer"] = run("midi-tokenizer", MidiTokenizer("b").feed, midi_unit, 5)
    tok, dec_midi = MidiTokenizer("b"), MidiDecoder("b", load_profile("nanokontrol2"))

    def midi_feed(data: bytes, t: float) -> list[Any]:
        return [e for m, mt in tok.feed(data, t) for e in dec_midi.decode(m, mt)]

    out["midi-tok+decode"] = run("midi-tok+decode", midi_feed, midi_unit, 4)
    dec = GenericDecoder("b", ReportDescriptor.parse(MAPLE_RDESC))
    other = bytearray(MAPLE_REPORT)
    other[1] = 1
    reports = [MAPLE_REPORT, bytes(other)] * 50_000
    t0 = time.perf_counter()
    count = sum(len(dec.decode(r, 0.0)) for r in reports)
    dt = time.perf_counter() - t0
    out["hid-generic"] = {"events_per_s": count / dt, "reports_per_s": len(reports) / dt}
    return out


# ---------------------------------------------------------------- network listeners: OSC and face streams
def _net_payloads() -> dict[str, tuple[str, Callable[[int], bytes]]]:
    """kind -> (spec, datagram i): a TouchOSC fader move, and one frame of each face stream in
    which one blendshape changes (so every frame gives an event)."""
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder

    from devices.facestream import ARKIT_NAMES
    from devices.facestream.facecap import FACECAP_ORDER
    from devices.facestream.livelink import encode_frame

    def msg(address: str, *args: Any) -> Any:
        b = OscMessageBuilder(address)
        for a in args:
            b.add_arg(a)
        return b.build()

    def bundle(msgs: list[Any]) -> bytes:
        b = OscBundleBuilder(IMMEDIATELY)
        for m in msgs:
            b.add_content(m)
        return b.build().dgram

    def w(i: int) -> float:
        return (i % 100) / 100

    def facecap(i: int) -> bytes:
        return bundle([msg("/W", k, w(i) if name == "jawOpen" else 0.1) for k, name in enumerate(FACECAP_ORDER)])

    def vmc(i: int) -> bytes:
        vals = [msg("/VMC/Ext/Blend/Val", n, w(i) if n == "jawOpen" else 0.1) for n in ARKIT_NAMES]
        return bundle(vals + [msg("/VMC/Ext/Blend/Apply")])

    def ifm(i: int) -> bytes:
        parts = [f"{n.replace('Left', '_L').replace('Right', '_R')}-{i % 100 if n == 'jawOpen' else 10}"
                 for n in ARKIT_NAMES]
        return ("|".join(parts) + "|=head#1.0,2.0,3.0,0.1,0.2,0.3|rightEye#1,2,3|leftEye#1,2,3|").encode()

    def livelink(i: int) -> bytes:
        return encode_frame({n: w(i) if n == "jawOpen" else 0.1 for n in ARKIT_NAMES})

    return {"osc": ("osc://127.0.0.1:0?profile=touchosc", lambda i: msg("/1/fader1", w(i)).dgram),
            "facecap": ("facecap://127.0.0.1:0", facecap), "vmc": ("vmc://127.0.0.1:0", vmc),
            "ifacialmocap": ("ifacialmocap://127.0.0.1:0", ifm), "livelink": ("livelink://127.0.0.1:0", livelink)}


def udp_sender(conn: Any) -> None:
    """The sender (a phone, another program), in its own process: (kind, port, i) -> send time."""
    import socket

    payloads = _net_payloads()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    conn.send("ready")
    while (job := conn.recv()) is not None:
        kind, port, i = job
        data = payloads[kind][1](i) if kind != "udp" else b"x" * 32
        t = time.monotonic()
        sock.sendto(data, ("127.0.0.1", port))
        conn.send(t)
    sock.close()


def net_latency(n: int, warmup: int = 20) -> dict[str, dict[str, float]]:
    """UDP send (in another process) -> event at a listener, for each listener; "udp" is the
    transport's own floor: a plain socket read by a blocking thread, stamped on return."""
    import socket

    parent, child = multiprocessing.get_context("fork").Pipe()
    proc = multiprocessing.get_context("fork").Process(target=udp_sender, args=(child,))
    proc.start()
    assert parent.recv() == "ready"
    arrived = threading.Event()
    stamp: list[float] = []
    out: dict[str, dict[str, float]] = {}

    def listener(event: Any) -> None:
        if isinstance(event, ControlEvent) and not stamp:
            stamp.append(time.monotonic())
            arrived.set()

    def measure(kind: str, port: int) -> dict[str, float]:
        lat: list[float] = []
        for i in range(n + warmup):
            arrived.clear()
            stamp.clear()
            parent.send((kind, port, i))
            if not arrived.wait(2.0):
                raise RuntimeError(f"{kind}: datagram {i} never arrived")
            t_send = parent.recv()
            if i >= warmup:
                lat.append((stamp[0] - t_send) * 1000)
            time.sleep(0.002)
        return {"n": len(lat), "p50_ms": statistics.median(lat), "p99_ms": percentile(lat, 99), "max_ms": max(lat)}

    try:
        floor = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        floor.bind(("127.0.0.1", 0))

        def plain_reader() -> None:
            while True:
                data = floor.recv(65536)
                if data == b"stop":
                    return
                listener(ControlEvent("udp", "x", "axis", 0.0))

        th = threading.Thread(target=plain_reader, daemon=True)
        th.start()
        out["udp"] = measure("udp", floor.getsockname()[1])
        floor.sendto(b"stop", floor.getsockname())
        th.join(2)
        floor.close()
        for kind, (spec, _) in _net_payloads().items():
            dev = open_device(spec)
            dev.add_listener(listener)
            dev.start()
            try:
                out[kind] = measure(kind, dev.bound[1])
            finally:
                dev.close()
    finally:
        parent.send(None)
        proc.join(5)
    return out


def net_throughput() -> dict[str, dict[str, float]]:
    """Each network parser alone: datagrams/s and events/s."""
    from devices.facestream.facecap import FaceCapParser
    from devices.facestream.ifacialmocap import IFacialMocapParser
    from devices.facestream.livelink import LiveLinkParser
    from devices.facestream.vmc import VmcParser
    from devices.osc import PROFILES, OscParser

    payloads = _net_payloads()
    bundle52 = _net_payloads()["vmc"][1]  # 53 messages: the heaviest OSC frame here
    parsers: dict[str, tuple[Callable[[bytes, float], list[Any]], Callable[[int], bytes]]] = {
        "osc message": (OscParser("b", PROFILES["touchosc"]).feed, payloads["osc"][1]),
        "osc 53-message bundle": (OscParser("b", PROFILES["generic"]).feed, bundle52),
        "facecap frame": (FaceCapParser("b").feed, payloads["facecap"][1]),
        "vmc frame": (VmcParser("b").feed, payloads["vmc"][1]),
        "ifacialmocap frame": (IFacialMocapParser("b").feed, payloads["ifacialmocap"][1]),
        "livelink frame": (LiveLinkParser("b").feed, payloads["livelink"][1]),
    }
    out = {}
    for name, (feed, make) in parsers.items():
        data = [make(i) for i in range(200)]
        reps = 10 if "frame" in name or "bundle" in name else 200
        t0 = time.perf_counter()
        count = sum(len(feed(d, 0.0)) for _ in range(reps) for d in data)
        dt = time.perf_counter() - t0
        out[name] = {"datagrams_per_s": reps * len(data) / dt, "events_per_s": count / dt}
    return out


def print_net(lat: dict[str, dict[str, float]], thr: dict[str, dict[str, float]]) -> None:
    floor = lat["udp"]
    print("latency: UDP send on 127.0.0.1 (another process) -> event at a listener")
    for name, r in lat.items():
        extra = "  (the transport alone: a plain socket and a blocking reader)" if name == "udp" else \
            f"  (p99 {r['p99_ms'] - floor['p99_ms']:+.3f} ms over the transport's)"
        print(f"  {name:<13} n={r['n']}  p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms  "
              f"max {r['max_ms']:.3f} ms{extra}")
    print("network parser throughput (parser alone)")
    for name, r in thr.items():
        print(f"  {name:<22} {r['datagrams_per_s']:>10,.0f} datagrams/s {r['events_per_s']:>10,.0f} events/s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=500, help="latency samples per backend")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--jack-periods", default="64,256", help="JACK periods (frames at 48 kHz) for the MIDI runs")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        results = {"latency": {"sgi": sgi_latency(args.events, tmp), "text": text_latency(args.events, tmp),
                               "rawmidi": rawmidi_latency(args.events, tmp)},
                   "throughput": throughput()}
        for period in (int(p) for p in args.jack_periods.split(",") if p):
            results["latency"][f"midi-jack-{period}"] = midi_jack_latency(args.events, period)
    results["net_latency"], results["net_throughput"] = net_latency(args.events), net_throughput()
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print("latency: last byte written on the box side -> event at a listener")
    for name, r in results["latency"].items():
        if "period_ms" in r:
            extra = (f"  (JACK period {r['period_ms']:.2f} ms; bare rtmidi callback p50 {r['bare_p50_ms']:.3f} ms"
                     f" p99 {r['bare_p99_ms']:.3f} ms; {r['lost']} lost in XRuns)")
        else:
            extra = f"  (+ {r['wire_ms']:.2f} ms wire time per report on real hardware)"
        print(f"  {name:<6} n={r['n']}  p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms  max {r['max_ms']:.3f} ms"
              + extra)
    print("parser throughput (parser alone, 4 KiB chunks)")
    for name, r in results["throughput"].items():
        extra = f"  {r['MB_per_s']:.1f} MB/s" if "MB_per_s" in r else f"  {r['reports_per_s']:,.0f} reports/s"
        print(f"  {name:<12} {r['events_per_s']:>12,.0f} events/s{extra}")
    print_net(results["net_latency"], results["net_throughput"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
