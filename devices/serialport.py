"""Shared plumbing of the serial-port backends (``sgi://``, ``serial://``, ``firmata://``).

Reads block in ``select`` and return as soon as one byte arrives, so latency is not bounded by a
poll interval; ``cancel_read`` wakes the reader for close and for queued host->box writes. On POSIX
the reader waits on pyserial's descriptors itself and takes whatever has arrived in one ``read``
(pyserial's ``read(in_waiting or 1)`` then ``in_waiting`` took one byte, asked the driver, and read
the rest of a packet in two more calls, each giving the interpreter's lock away and waiting to get
it back while the live loop held it). The port is reopened by path, so a box behind a stable udev symlink
(``/dev/serial/by-id/...``) comes back by itself after an unplug.
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
from collections import deque
from collections.abc import Iterable
from typing import Any

from devices.base import Device
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec


class SerialPortDevice(Device):
    """A device on a serial port; subclasses parse bytes and may talk to the box."""

    BAUDRATE = 9600
    OPTIONS = frozenset({"baud"})
    #: After this long without data, check that the path still names the port we hold.
    IDLE_CHECK = 0.5
    #: The most bytes one read takes (what a tty's input buffer holds).
    READ_CHUNK = 4096

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        if not spec.location:
            raise DeviceSpecError(f"{spec.text}: no port given; expected {self.FORM}")
        self.path = spec.location
        self.baudrate = spec.get_int("baud", self.BAUDRATE, lo=50, hi=4_000_000)
        self._port: Any = None
        self._write_lock = threading.Lock()
        self._outbox: deque[bytes] = deque()
        self._port_id: tuple[int, int] | None = None
        self._last_data = 0.0
        self._opened_once = False

    # ---------------------------------------------------------------- port handling
    def _open(self) -> None:
        import serial  # lazily: pyserial is only needed by serial backends

        self._close_handle()
        try:
            self._port = serial.Serial(self.path, self.baudrate, timeout=self.read_timeout, write_timeout=1.0)
        except serial.SerialException as err:
            if err.errno == errno.EACCES:
                raise OSError(f"{self.path}: permission denied; add your user to the 'dialout' group "
                              "(sudo usermod -aG dialout $USER, then log in again)") from err
            raise
        self._opened_once = True
        self._port_id = self._identity()
        self._last_data = time.monotonic()
        self._handshake()

    def address_exists(self) -> bool:
        """The port's path exists or it opened at least once (a box behind it may still be
        powering up, or its first contact failed half-way)."""
        return self._opened_once or os.path.exists(self.path)

    def _identity(self) -> tuple[int, int] | None:
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return (st.st_rdev, st.st_ino)

    def _close_handle(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            port.close()

    def _wake(self) -> None:
        port = self._port
        if port is not None and hasattr(port, "cancel_read"):
            try:
                port.cancel_read()
            except Exception:
                pass

    def write(self, data: bytes, pace: float = 0.0) -> None:
        """Send bytes to the box; with ``pace`` > 0 one byte at a time, ``pace`` seconds apart,
        for boxes that choke on bursts (the SGI box)."""
        port = self._port
        if port is None:
            raise OSError("port not open")
        with self._write_lock:
            if pace <= 0:
                port.write(data)
                return
            for i in range(len(data)):
                port.write(data[i : i + 1])
                time.sleep(pace)

    def send_later(self, data: bytes) -> None:
        """Queue bytes for the reader thread to write, so a caller (the live loop setting a light)
        never blocks on a slow or vanished port."""
        self._outbox.append(data)
        self._wake()

    def _flush_outbox(self) -> None:
        while self._outbox:
            self.write(self._outbox.popleft())

    def read_raw(self, timeout: float) -> tuple[bytes, float]:
        """Whatever bytes arrive within ``timeout`` (returns at the first byte) and the monotonic
        time taken right after the read."""
        port = self._port
        if port is None:
            raise OSError("port not open")
        fd, abort = getattr(port, "fd", None), getattr(port, "pipe_abort_read_r", None)
        if isinstance(fd, int) and isinstance(abort, int):  # pyserial on POSIX: its descriptors directly
            return self._read_fd(fd, abort, timeout)
        if port.timeout != timeout:  # the setter reconfigures the tty (tcsetattr): only on change
            port.timeout = timeout
        data = port.read(port.in_waiting or 1)
        t = time.monotonic()
        if data:
            waiting = port.in_waiting
            if waiting:
                data += port.read(waiting)
        return data, t

    def _read_fd(self, fd: int, abort: int, timeout: float) -> tuple[bytes, float]:
        """`read_raw` on the port's descriptor: wait for input or `cancel_read` (pyserial's abort
        pipe), then one non-blocking read of all that is there."""
        ready, _, _ = select.select([fd, abort], [], [], max(0.0, timeout))
        if abort in ready:
            try:
                os.read(abort, 1000)
            except BlockingIOError:
                pass
        if fd not in ready:
            return b"", time.monotonic()
        try:
            data = os.read(fd, self.READ_CHUNK)
        except BlockingIOError:  # taken by someone else between the select and the read
            return b"", time.monotonic()
        t = time.monotonic()
        if not data:  # a vanished USB adapter: always readable, never any data
            raise OSError(f"{self.path}: the port reports input but gives none (unplugged?)")
        return data, t

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        self._flush_outbox()
        self._before_read()
        data, t = self.read_raw(timeout)
        if not data:
            if t - self._last_data > self.IDLE_CHECK:
                self._last_data = t
                if self._identity() != self._port_id:
                    raise OSError(f"{self.path} vanished or now names another port")
            return ()
        self._last_data = t
        return self._parse(data, t)

    # ---------------------------------------------------------------- hooks
    def _handshake(self) -> None:
        """Talk to the box after opening (reset, enable reports); raise OSError if it is not there."""

    def _before_read(self) -> None:
        """Run queued host->box work in the reader thread (it owns the pacing)."""

    def _parse(self, data: bytes, t: float) -> list[ControlEvent]:
        raise NotImplementedError
