"""Bursts into real UDP sockets on 127.0.0.1: a listener's receive buffer holds a burst that
overflows a socket of the default size, and what overflows is counted, from the kernel's own
counter, exactly: every datagram sent is either read or counted as dropped."""

from __future__ import annotations

import socket
import time

from netdev import osc_message

import devices
from devices.udpstats import DEFAULT_RCVBUF, proc_drops

WAIT = 5.0  # a liveness bound, not a timing claim


def _burst(port: int, n: int) -> None:
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for i in range(n):
            tx.sendto(osc_message("/face/channel/jaw", (i % 100) / 100.0), ("127.0.0.1", port))
    finally:
        tx.close()


def _read_all(dev: object, sent: int) -> None:
    """Start the reader and wait until every datagram is read or counted dropped."""
    dev.start()  # type: ignore[attr-defined]
    deadline = time.monotonic() + WAIT
    while time.monotonic() < deadline:
        if dev.datagrams + dev.drops >= sent:  # type: ignore[attr-defined]
            return
        time.sleep(0.05)


def test_a_burst_that_overflows_a_default_socket_is_held_whole() -> None:
    n = 2000
    plain = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    plain.bind(("127.0.0.1", 0))
    dev = devices.open_device("osc://127.0.0.1:0?max_rate=10000000")
    try:
        _burst(plain.getsockname()[1], n)
        plain_drops = proc_drops(plain)
        assert plain_drops is not None and plain_drops > 0  # the default buffer cannot hold it
        assert dev.rcvbuf_granted >= DEFAULT_RCVBUF  # what the kernel granted, read back
        assert dev.drops == 0
        _burst(dev.bound[1], n)  # type: ignore[attr-defined]
        _read_all(dev, n)
        assert (dev.datagrams, dev.drops) == (n, 0)
    finally:
        plain.close()
        dev.close()


def test_a_flood_is_counted_from_the_kernel_and_every_datagram_accounted_for() -> None:
    n = 3000
    dev = devices.open_device("osc://127.0.0.1:0?rcvbuf=65536&max_rate=10000000")
    try:
        port = dev.bound[1]  # type: ignore[attr-defined]
        _burst(port, n)  # nobody reads while it arrives: a small buffer must overflow
        _read_all(dev, n)
        assert dev.drops > 0 and dev.datagrams + dev.drops == n
        first = dev.drops
        # a second flood: the count goes on (the kernel's total for the socket), still exact
        dev.datagrams = 0
        _burst(port, n)
        deadline = time.monotonic() + WAIT
        while dev.datagrams + dev.drops - first < n and time.monotonic() < deadline:
            time.sleep(0.05)
        assert dev.datagrams + dev.drops - first == n
    finally:
        dev.close()


def test_what_waited_before_the_reader_started_is_a_backlog_not_a_flood() -> None:
    """A phone streams while a cold show prepares its face (the device is open, nobody reads):
    when the reader starts, the queued datagrams are read at once without the flood warning and
    none is thrown away; a flood after that is still bounded by max_rate."""
    n = 1000
    dev = devices.open_device("livelink://127.0.0.1:0?max_rate=1000")  # 100 a window of 0.1 s
    try:
        from devices.facestream.livelink import encode_frame

        port = dev.bound[1]  # type: ignore[attr-defined]
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(n):
            tx.sendto(encode_frame({"jawOpen": i / n}, frame=i), ("127.0.0.1", port))
        _read_all(dev, n)
        assert (dev.datagrams, dev.drops) == (n, 0)
        assert dev.warnings.counts["flood"] == 0
        for i in range(20 * n):  # then far more than 1000 a second: bounded
            tx.sendto(encode_frame({"jawOpen": 0.5}, frame=i), ("127.0.0.1", port))
        tx.close()
        deadline = time.monotonic() + WAIT
        while dev.warnings.counts["flood"] == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert dev.warnings.counts["flood"] > 0
    finally:
        dev.close()
