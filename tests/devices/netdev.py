"""Helpers for the network listener tests: a started device on a free 127.0.0.1 port, a sender
socket, and waiting for events without sleeping blindly. Everything stays on 127.0.0.1."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

import devices
from devices.events import ControlEvent

WAIT = 5.0  # seconds to wait for something that must happen (a liveness bound, not a timing claim)


def osc_message(address: str, *args: Any) -> bytes:
    """One OSC message datagram (python-osc's builder, as senders use it)."""
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(a)
    return b.build().dgram


def osc_bundle(messages: list[bytes], timetag: float = IMMEDIATELY) -> bytes:
    """A bundle of message datagrams; ``timetag`` in seconds since 1970 (or IMMEDIATELY)."""
    from pythonosc.osc_message import OscMessage

    b = OscBundleBuilder(timetag)
    for m in messages:
        b.add_content(OscMessage(m))
    return b.build().dgram


class Listener:
    """A started device plus a sender socket on 127.0.0.1."""

    def __init__(self, dev: Any) -> None:
        self.dev = dev
        self.q = devices.EventQueue()
        dev.add_listener(self.q)
        dev.start()
        self.port = dev.bound[1]
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))

    def send(self, *datagrams: bytes) -> None:
        for d in datagrams:
            self.sock.sendto(d, ("127.0.0.1", self.port))

    def events(self, until: Callable[[list[ControlEvent]], bool], timeout: float = WAIT) -> list[ControlEvent]:
        """Control events collected until ``until(events)`` holds (or the timeout passes)."""
        got: list[ControlEvent] = []
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            e = self.q.get(timeout=0.05)
            if isinstance(e, ControlEvent):
                got.append(e)
            if until(got):
                break
        return got

    def control_events(self, control: str, n: int = 1) -> list[ControlEvent]:
        """Wait for ``n`` events of ``control``; return every control event seen meanwhile."""
        return self.events(lambda es: sum(e.control == control for e in es) >= n)

    def wait_for(self, cond: Callable[[], bool], timeout: float = WAIT) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if cond():
                return True
            time.sleep(0.01)
        return cond()

    def close(self) -> None:
        self.sock.close()
        self.dev.close()


@contextmanager
def listening(spec: str) -> Iterator[Listener]:
    """``spec`` opened and started (use port 0 for a free port)."""
    lis = Listener(devices.open_device(spec))
    try:
        yield lis
    finally:
        lis.close()
