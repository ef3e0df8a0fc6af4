"""``rawmidi:///dev/snd/midiC1D0[?profile=P&channel=N]`` and DIN MIDI on a UART
(``rawmidi:///dev/ttyAMA0?baud=31250``): the raw MIDI byte stream, read with the project's own
tokenizer (running status, real-time bytes anywhere, capped SysEx).

The node is opened non-blocking (a rawmidi node held by another program would otherwise block in
the kernel) and read in ``select`` with a wake-up pipe, so a byte reaches the tokenizer as soon as
it arrives. With ``baud`` the path is a serial port, configured raw at that rate by pyserial.
Unplugging shows up as ENODEV/EIO or end of file, and the path is re-checked when idle; both
raise OSError, so the base class reports ``lost`` and reopens the path every 0.2 s. The card's
name (``/proc/asound/cardN/id``) picks the profile when none is given.
"""

from __future__ import annotations

import os
import re
import select
import time
from collections.abc import Iterable
from typing import Any

from devices.events import ControlEvent
from devices.midi.common import MidiDevice, check_location
from devices.midi.profile import profile_for_port
from devices.midi.tokenizer import MidiTokenizer
from devices.spec import DeviceSpec
from devices.wakepipe import SelectWaking, WakePipe

#: After this long without data, check that the path still names the node we hold.
IDLE_CHECK = 0.5


def card_name(path: str) -> str:
    """The ALSA card id of a ``midiC<card>D<dev>`` node ('' when unknown)."""
    m = re.search(r"midiC(\d+)D\d+$", path)
    if not m:
        return ""
    try:
        with open(f"/proc/asound/card{m.group(1)}/id", encoding="utf-8") as fh:
            return fh.read().strip()
    except OSError:
        return ""


class RawMidiDevice(SelectWaking, MidiDevice):
    """A MIDI byte stream on a rawmidi node, a serial port or anything with a file descriptor."""

    scheme = "rawmidi"
    FORM = "rawmidi:///dev/snd/midiC1D0[?profile=P&channel=N] or rawmidi:///dev/ttyUSB0?baud=31250"
    OPTIONS = frozenset({"profile", "channel", "baud"})

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        check_location(spec, self.FORM)
        if "profile" not in spec.query:
            name = card_name(spec.location)
            if name:
                spec = DeviceSpec(spec.text, spec.scheme, spec.location, {**spec.query, "profile": profile_for_port(name)})
        super().__init__(spec, **options)
        self.path = spec.location
        self.baud = spec.get_int("baud", 0, lo=50, hi=4_000_000) if "baud" in spec.query else 0
        self.description = f"{self.profile.title} on {self.path}" + (f" at {self.baud} baud" if self.baud else "")
        self.tokenizer = MidiTokenizer(self.spec, warnings=self.warnings)
        self._fd = -1
        self._serial: Any = None
        self._identity: tuple[int, int] | None = None
        self._waker = WakePipe()
        self._last_data = 0.0

    def _stat(self) -> tuple[int, int] | None:
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return (st.st_rdev, st.st_ino)

    def _open(self) -> None:
        self._close_handle()
        if self.baud:
            import serial  # lazily: only DIN MIDI on a UART needs pyserial

            self._serial = serial.Serial(self.path, self.baud, timeout=0, write_timeout=0.5)
            self._fd = self._serial.fileno()
        else:
            try:
                self._fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            except PermissionError:  # an input-only node, or write access not granted: no lights
                self._fd = os.open(self.path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        self._identity = self._stat()
        self._last_data = time.monotonic()
        self.tokenizer.reset()
        self.decoder.reset()
        self.feedback.forget_sent()

    def _close_handle(self) -> None:
        ser, self._serial = self._serial, None
        fd, self._fd = self._fd, -1
        if ser is not None:
            ser.close()
        elif fd >= 0:
            os.close(fd)

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        fd = self._fd
        if fd < 0:
            raise OSError("not open")
        due = self._send_lights(time.monotonic())
        wait = timeout if due is None else max(0.0, min(timeout, due - time.monotonic()))
        ready, _, _ = select.select([fd, self._waker], [], [], wait)
        if self._waker in ready:
            self._waker.drain()
        if fd not in ready:
            now = time.monotonic()
            if now - self._last_data > IDLE_CHECK:
                self._last_data = now
                if self._stat() != self._identity:
                    raise OSError(f"{self.path} vanished or now names another device")
            return ()
        try:
            data = os.read(fd, 4096)
        except BlockingIOError:
            return ()
        t = time.monotonic()
        if not data:
            raise OSError(f"{self.path}: end of stream (unplugged)")
        self._last_data = t
        events: list[ControlEvent] = []
        for msg, mt in self.tokenizer.feed(data, t):
            events += self._decode(msg, mt)
        self._send_lights(time.monotonic())
        return events

    def _send_lights(self, now: float) -> float | None:
        msgs, nxt = self.feedback.due(now)
        if msgs and self._fd >= 0:
            data = b"".join(bytes(m) for m in msgs)
            try:
                os.write(self._fd, data)
            except (BlockingIOError, PermissionError):
                self.warnings.warn("light", f"{self.path}: lights not sent (port busy or read-only)")
            except OSError as err:
                if err.errno == 9:  # EBADF: opened read-only
                    self.warnings.warn("light", f"{self.path}: opened read-only; lights not sent")
                else:
                    raise
        return nxt
