"""Emulators of control boxes behind real pseudo-terminals, for end-to-end backend tests.

``PtyPort`` is the cable: a pty whose slave is reached through a symlink in a temp dir, so a test
can unplug it (close the pty, remove the link) and replug it (a new pty behind the same link), the
way a USB-serial adapter comes back under the same /dev/serial/by-id name. Box emulators read what
the host sends on the master side and answer like the hardware.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from pathlib import Path


class PtyPort:
    """A pty exposed as ``link``; ``on_bytes`` gets what the host writes."""

    def __init__(self, link: Path, on_bytes: object = None) -> None:
        self.link = Path(link)
        self.on_bytes = on_bytes
        self.master = -1
        self.slave = -1
        self._write_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.plug()

    def plug(self) -> None:
        """Create a fresh pty and point the link at it (atomically), then serve it."""
        master, slave = os.openpty()
        tty.setraw(slave)
        tmp = self.link.with_name(self.link.name + ".new")
        if tmp.is_symlink():
            tmp.unlink()
        tmp.symlink_to(os.ttyname(slave))
        os.replace(tmp, self.link)
        self.master, self.slave = master, slave  # the slave stays open so the pty lives
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, args=(master, self._stop), daemon=True)
        self._thread.start()

    def unplug(self) -> None:
        """Pull the cable: the host's next read fails and the path disappears."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2)
        if self.link.is_symlink():
            self.link.unlink()
        for fd in (self.master, self.slave):
            if fd >= 0:
                os.close(fd)
        self.master = self.slave = -1

    close = unplug

    def write(self, data: bytes) -> None:
        """Bytes from the box to the host."""
        with self._write_lock:
            view = memoryview(data)
            while view:
                n = os.write(self.master, view)
                view = view[n:]

    def _serve(self, master: int, stop: threading.Event) -> None:
        while not stop.is_set():
            try:
                ready, _, _ = select.select([master], [], [], 0.02)
                if not ready:
                    continue
                data = os.read(master, 4096)
            except OSError:
                if stop.wait(0.01):
                    return
                continue
            if data and self.on_bytes is not None:
                self.on_bytes(data)  # type: ignore[operator]


class SgiBoxEmulator:
    """The SGI dial-and-button box: answers reset, honours enables, keeps int16 dial counters,
    records LED masks and every command received."""

    def __init__(self, link: Path, acks: int = 1, ack_delay: float = 0.002, keep_counters: bool = False,
                 hang_up_first: bool = False) -> None:
        self.acks = acks
        #: a flaky first contact: the first reset hangs up the line (the host's first open fails
        #: with an I/O error) and the box comes back behind the same path a moment later
        self.hang_up_first = hang_up_first
        self.ack_delay = ack_delay
        self.keep_counters = keep_counters
        self.counters = [0] * 8
        self.dials_on = False
        self.buttons_on = False
        self.leds = 0
        self.commands: list[bytes] = []
        self.resets = 0
        self.ready = threading.Event()
        self.leds_changed = threading.Condition()
        self._pending = b""
        self.port = PtyPort(link, self._on_bytes)

    _ARGS = {0x20: 0, 0x50: 2, 0x51: 2, 0x53: 2, 0x73: 4, 0x71: 4, 0x75: 4, 0x4B: 0, 0x4C: 0, 0x61: 8}

    def _on_bytes(self, data: bytes) -> None:
        self._pending += data
        while self._pending:
            cmd = self._pending[0]
            n = self._ARGS.get(cmd)
            if n is None:  # unknown host byte: a real box ignores it
                self._pending = self._pending[1:]
                continue
            if len(self._pending) < 1 + n:
                return
            packet, self._pending = self._pending[: 1 + n], self._pending[1 + n :]
            self.commands.append(packet)
            self._execute(packet)

    def _execute(self, packet: bytes) -> None:
        cmd = packet[0]
        if cmd == 0x20 and self.hang_up_first:
            self.hang_up_first = False
            threading.Thread(target=self._hang_up, daemon=True).start()
            return
        if cmd == 0x20:
            self.resets += 1
            self.dials_on = self.buttons_on = False
            self.ready.clear()
            if not self.keep_counters:
                self.counters = [0] * 8
            time.sleep(self.ack_delay)
            self.port.write(bytes([0x20]) * self.acks)
        elif cmd == 0x50:
            self.dials_on = True
            self.buttons_on = False  # the documented quirk: enabling dials disables buttons
        elif cmd == 0x73:
            self.buttons_on = True
            if self.dials_on:
                self.ready.set()
        elif cmd == 0x75:
            with self.leds_changed:
                self.leds = packet[1] | packet[2] << 8 | packet[3] << 16 | packet[4] << 24
                self.leds_changed.notify_all()

    def _hang_up(self) -> None:
        self.unplug()
        time.sleep(0.1)
        self.replug()

    def wait_ready(self, timeout: float = 5.0) -> None:
        assert self.ready.wait(timeout), f"host never finished the init; got {self.commands}"

    def wait_leds(self, pred: object, timeout: float = 5.0) -> int:
        with self.leds_changed:
            assert self.leds_changed.wait_for(lambda: pred(self.leds), timeout), f"leds {self.leds:#x}"  # type: ignore[operator]
            return self.leds

    def dial_packet(self, n: int, counts: int) -> bytes:
        """Turn dial ``n`` by ``counts`` and return the report the box would send."""
        v = (self.counters[n] + counts + 0x8000) % 0x10000 - 0x8000
        self.counters[n] = v
        return bytes([0x30 + n, (v >> 8) & 0xFF, v & 0xFF])

    def turn(self, n: int, counts: int) -> None:
        pkt = self.dial_packet(n, counts)
        if self.dials_on:
            self.port.write(pkt)

    def button(self, k: int, pressed: bool) -> None:
        if self.buttons_on:
            self.port.write(bytes([(0xC0 if pressed else 0xE0) + (k ^ 0x18)]))

    def spontaneous_reset(self) -> None:
        """The box power-cycled: it says 0x20 and forgets its enables."""
        self.dials_on = self.buttons_on = False
        self.ready.clear()
        self.counters = [0] * 8
        self.port.write(bytes([0x20]))

    def unplug(self) -> None:
        self.port.unplug()
        self.dials_on = self.buttons_on = False
        self.ready.clear()

    def replug(self) -> None:
        """Plug the box back in: it powers up with empty buffers and zeroed counters."""
        self.counters = [0] * 8
        self._pending = b""
        self.port.plug()


class TextBoxEmulator:
    """A home-made box speaking the text protocol; records the host's light commands."""

    def __init__(self, link: Path) -> None:
        self.received = b""
        self.got_line = threading.Condition()
        self.port = PtyPort(link, self._on_bytes)

    def _on_bytes(self, data: bytes) -> None:
        with self.got_line:
            self.received += data
            self.got_line.notify_all()

    def lines(self) -> list[str]:
        return self.received.decode("ascii", "replace").splitlines()

    def wait_line(self, line: str, timeout: float = 5.0) -> None:
        with self.got_line:
            assert self.got_line.wait_for(lambda: line in self.lines(), timeout), self.lines()

    def send(self, text: str) -> None:
        self.port.write(text.encode("ascii"))


class FirmataEmulator:
    """An Arduino running StandardFirmata (+ FirmataEncoder): answers the version and firmware
    queries, records pin modes, reporting enables and the sampling interval, and reports inputs
    only once the host enabled them, as the firmware does."""

    def __init__(self, link: Path, name: str = "StandardFirmata.ino") -> None:
        self.name = name
        self.pin_modes: dict[int, int] = {}
        self.report_analog: set[int] = set()
        self.report_ports: set[int] = set()
        self.sampling_ms: int | None = None
        self.encoders: dict[int, tuple[int, int]] = {}
        self.levels = [1] * 24  # pull-ups: idle high
        self.configured = threading.Event()
        self._pending = b""
        self.port = PtyPort(link, self._on_bytes)

    def _on_bytes(self, data: bytes) -> None:
        self._pending += data
        while self._pending:
            b = self._pending[0]
            if b == 0xF9:
                self._pending = self._pending[1:]
                self.port.write(bytes([0xF9, 2, 5]))
            elif b == 0xF0:
                end = self._pending.find(0xF7)
                if end < 0:
                    return
                self._sysex(self._pending[1:end])
                self._pending = self._pending[end + 1 :]
            elif b == 0xF4 or b & 0xF0 in (0xC0, 0xD0):
                n = 3 if b == 0xF4 else 2
                if len(self._pending) < n:
                    return
                msg, self._pending = self._pending[:n], self._pending[n:]
                if b == 0xF4:
                    self.pin_modes[msg[1]] = msg[2]
                elif b & 0xF0 == 0xC0 and msg[1]:
                    self.report_analog.add(b & 0x0F)
                elif b & 0xF0 == 0xD0 and msg[1]:
                    self.report_ports.add(b & 0x0F)
                    self.configured.set()
            else:
                self._pending = self._pending[1:]

    def _sysex(self, body: bytes) -> None:
        if body[:1] == b"\x79":
            text = b"".join(bytes([ord(c) & 0x7F, ord(c) >> 7]) for c in self.name)
            self.port.write(bytes([0xF0, 0x79, 2, 5]) + text + b"\xf7")
        elif body[:1] == b"\x7a":
            self.sampling_ms = body[1] | body[2] << 7
        elif body[:2] == b"\x61\x00":
            self.encoders[body[2]] = (body[3], body[4])

    def analog(self, ch: int, value: int) -> None:
        if ch in self.report_analog:
            self.port.write(bytes([0xE0 | ch, value & 0x7F, (value >> 7) & 0x7F]))

    def digital(self, pin: int, level: int) -> None:
        self.levels[pin] = level
        port = pin // 8
        if port in self.report_ports:
            mask = sum(self.levels[port * 8 + i] << i for i in range(8))
            self.port.write(bytes([0x90 | port, mask & 0x7F, mask >> 7]))

    def encoder(self, n: int, position: int) -> None:
        mag = abs(position)
        head = n | (0x40 if position < 0 else 0)
        self.port.write(bytes([0xF0, 0x61, head, mag & 0x7F, (mag >> 7) & 0x7F, (mag >> 14) & 0x7F,
                               (mag >> 21) & 0x7F, 0xF7]))
