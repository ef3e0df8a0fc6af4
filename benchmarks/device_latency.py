"""Device latency and parser throughput.

1. Latency: a box emulator, in a separate process like real hardware, writes a report into a
   pseudo-terminal; we time from the write of the report's last byte to the moment the event
   reaches a listener of a started device (pyserial read in select, parse, dispatch). The bytes are paced at the line's byte time (the pty itself has no
   baud rate), so on real hardware add the wire time of one report to these numbers: 3 bytes at
   9600 baud ~ 3.1 ms for the SGI box, a 6-byte line at 115200 baud ~ 0.5 ms for the text protocol.
2. Throughput: each parser alone, fed a long valid byte stream in 4 KiB chunks.

Run:  .venv/bin/python benchmarks/device_latency.py [--events N] [--json]
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
        if kind == "sgi":
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
    dec = GenericDecoder("b", ReportDescriptor.parse(MAPLE_RDESC))
    other = bytearray(MAPLE_REPORT)
    other[1] = 1
    reports = [MAPLE_REPORT, bytes(other)] * 50_000
    t0 = time.perf_counter()
    count = sum(len(dec.decode(r, 0.0)) for r in reports)
    dt = time.perf_counter() - t0
    out["hid-generic"] = {"events_per_s": count / dt, "reports_per_s": len(reports) / dt}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=500, help="latency samples per backend")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        results = {"latency": {"sgi": sgi_latency(args.events, tmp), "text": text_latency(args.events, tmp)},
                   "throughput": throughput()}
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print("latency: last byte written on the box side -> event at a listener")
    for name, r in results["latency"].items():
        print(f"  {name:<6} n={r['n']}  p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms  max {r['max_ms']:.3f} ms"
              f"  (+ {r['wire_ms']:.2f} ms wire time per report on real hardware)")
    print("parser throughput (parser alone, 4 KiB chunks)")
    for name, r in results["throughput"].items():
        extra = f"  {r['MB_per_s']:.1f} MB/s" if "MB_per_s" in r else f"  {r['reports_per_s']:,.0f} reports/s"
        print(f"  {name:<12} {r['events_per_s']:>12,.0f} events/s{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
