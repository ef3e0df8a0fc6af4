"""The shared plumbing of every network listener (``osc://``, ``facecap://``, ``vmc://``,
``ifacialmocap://``, ``livelink://``): one UDP socket read by the device's reader thread.

Security first: the socket binds 127.0.0.1 unless the spec names another address *and* says
``lan=1``; a LAN listener prints what it exposes when it opens, and ``allow=ADDR[,NET/BITS...]``
drops datagrams from every other sender. Nothing is ever sent back to a sender.

Bursts: the socket asks for a receive buffer of ``rcvbuf`` bytes (4 MiB by default; what the
kernel granted is ``rcvbuf_granted``) and ``drops`` counts the datagrams lost to overflow, from the
kernel's own counter (see devices.udpstats), plus any this reader discarded over ``max_rate``.

Robustness: datagrams above ``max_size`` bytes are dropped and counted; at most ``max_rate``
datagrams a second are decoded (a flood beyond that waits in, and is then dropped by, the kernel's
socket buffer, which costs this process nothing); a batch of reads is bounded, and absolute values
of one control within a batch are coalesced to the last, so a burst never floods the live loop.
What waited in the buffer before the reader started (a sender that streamed while a show prepared
its face) is read at once without counting against ``max_rate``: it is a backlog, not a flood.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import sys
import time
from collections.abc import Iterable
from typing import Any, ClassVar

from devices.base import Device
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from devices.udpstats import (ANC_SIZE, DEFAULT_RCVBUF, ancillary_drops, enable_drop_counter, proc_drops,
                              size_receive_buffer)
from devices.wakepipe import SelectWaking, WakePipe

Network = ipaddress.IPv4Network | ipaddress.IPv6Network

#: Datagrams read per ``_read`` call at most, so listeners get events while a burst goes on.
BATCH = 256
#: The flood budget is counted over windows of this many seconds.
WINDOW = 0.1
#: Largest datagram the socket can hold (IPv4's UDP payload limit).
RECV_BUFFER = 65536
#: /proc/net/udp is read for drops at most this often (seconds), when nothing arrives.
PROC_EVERY = 0.5
#: The backlog found when reading starts is read without the flood budget, at most as many
#: datagrams as the receive buffer can hold (a datagram takes at least this many of its bytes).
BACKLOG_BYTES = 256


def split_host_port(location: str, default_port: int, spec: str) -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT``, ``HOST``, ``[v6]:PORT`` or nothing -> (host, port); the host
    defaults to 127.0.0.1."""
    host, port_text = location.strip(), ""
    if host.startswith("["):
        end = host.find("]")
        if end < 0:
            raise DeviceSpecError(f"{spec}: bad address {location!r}; expected [IPV6]:PORT")
        host, port_text = host[1:end], host[end + 1:].removeprefix(":")
    elif host.count(":") == 1:
        host, port_text = host.split(":")
    elif host.count(":") > 1:
        raise DeviceSpecError(f"{spec}: write an IPv6 address in brackets: [{host}]:PORT")
    host = host.strip("/") or "127.0.0.1"
    port = default_port
    if port_text:
        if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise DeviceSpecError(f"{spec}: port {port_text!r} is not a number 0..65535")
        port = int(port_text)
    return host, port


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``; other names are resolved."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_DGRAM)
    except OSError:
        return False  # unresolvable: opening will fail and say so
    return bool(infos) and all(ipaddress.ip_address(i[4][0]).is_loopback for i in infos)


def parse_allow(text: str | None, spec: str) -> tuple[Network, ...]:
    """``allow=192.168.1.20,10.0.0.0/24`` -> networks; a bad entry names itself."""
    if text is None:
        return ()
    nets = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        try:
            nets.append(ipaddress.ip_network(item, strict=False))
        except ValueError as err:
            raise DeviceSpecError(f"{spec}: allow={item!r} is not an IP address or ADDR/BITS network") from err
    if not nets:
        raise DeviceSpecError(f"{spec}: allow= needs at least one address, e.g. allow=192.168.1.20")
    return tuple(nets)


def sender_allowed(address: str, allow: tuple[Network, ...]) -> bool:
    """Whether a datagram from ``address`` may be decoded (everyone, without an allow-list)."""
    if not allow:
        return True
    try:
        ip = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return any(ip.version == net.version and ip in net for net in allow)


def local_addresses() -> list[str]:
    """This machine's non-loopback addresses as far as the host name tells (best effort)."""
    out: list[str] = []
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None, type=socket.SOCK_DGRAM):
            addr = str(info[4][0])
            if not ipaddress.ip_address(addr.split("%", 1)[0]).is_loopback and addr not in out:
                out.append(addr)
    except (OSError, ValueError):
        pass
    return out


def exposure_text(spec: str, what: str, host: str, port: int, allow: tuple[Network, ...]) -> str:
    """The line a LAN listener prints when it opens: what it exposes, to whom."""
    if host in ("0.0.0.0", "::", ""):
        seen = local_addresses()
        where = "every network interface" + (f" ({', '.join(seen)})" if seen else "")
    else:
        where = host
    names = [str(n.network_address) if n.prefixlen == n.max_prefixlen else str(n) for n in allow]
    who = ("only datagrams from " + ", ".join(names) + " are used") if allow else \
        "any machine that can reach it can drive the face; limit the senders with allow=ADDR[,ADDR...]"
    return f"{spec}: listening for {what} on UDP port {port} of {where}: {who}"


class UdpListenerDevice(SelectWaking, Device):
    """A device fed by UDP datagrams. Subclasses set ``DEFAULT_PORT``, ``WHAT`` and implement
    ``_datagram(data, t, sender)``; ``_idle(t)`` may emit events when nothing arrives."""

    DEFAULT_PORT: ClassVar[int] = 9000
    #: What the datagrams carry, for the LAN notice ("OSC", "Face Cap face tracking", ...).
    WHAT: ClassVar[str] = "datagrams"
    NET_OPTIONS: ClassVar[frozenset[str]] = frozenset({"lan", "allow", "max_size", "max_rate", "rcvbuf"})
    MAX_SIZE: ClassVar[int] = 32768

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        self.host, self.port = split_host_port(spec.location, self.DEFAULT_PORT, spec.text)
        self.lan = spec.get_bool("lan", False)
        if self.lan and not spec.location.strip().strip("/").partition(":")[0]:
            self.host = "0.0.0.0"  # `osc://:9000?lan=1`: no address named, every interface (as panel://)
        elif self.lan and is_loopback(self.host):
            # `osc://127.0.0.1:9000?lan=1` listened on this machine alone: the phone never reached it
            raise DeviceSpecError(
                f"{spec.text}: lan=1 asks for the LAN, but {self.host} is this machine alone; listen on "
                f"every interface with {self.scheme}://0.0.0.0:{self.port}?lan=1 (or one of this machine's "
                "addresses)")
        self.allow = parse_allow(spec.query.get("allow"), spec.text)
        self.max_size = spec.get_int("max_size", self.MAX_SIZE, lo=64, hi=65507)
        self.max_rate = spec.get_int("max_rate", 20000, lo=10, hi=10_000_000)
        self.rcvbuf = spec.get_int("rcvbuf", DEFAULT_RCVBUF, lo=4096, hi=1 << 28)
        self.rcvbuf_granted = 0
        self.discarded = 0  # read but thrown away over max_rate
        self._drops_before = 0  # kernel drops of the sockets of earlier connections
        self._sock_drops = 0  # the current socket's kernel drop total, as last seen
        self._ancillary = False
        self._proc_read = 0.0
        if not self.lan and not is_loopback(self.host):
            shown = f"[{self.host}]" if ":" in self.host else self.host  # the spec to type: 'facecap://:::8080' was no spec
            raise DeviceSpecError(
                f"{spec.text}: {self.host} would listen beyond this machine; say so with lan=1 "
                f"({self.scheme}://{shown}:{self.port}?lan=1, and allow=ADDR,... to accept only those "
                f"senders), or use 127.0.0.1")
        self.parsed_host = self.host
        self.exposure = "" if is_loopback(self.host) else \
            exposure_text(spec.text, self.WHAT, self.host, self.port, self.allow)
        self.description = f"{self.WHAT} on udp {self.host}:{self.port}"
        self.bound: tuple[str, int] | None = None
        self.datagrams = 0
        self.refused = 0
        self._sock: socket.socket | None = None
        self._waker = WakePipe()
        self._buf = bytearray(RECV_BUFFER)
        self._window_start = 0.0
        self._window_count = 0
        # datagrams queued while nobody read (between opening and the reader's start, e.g. while a
        # show prepares its face): read in one go, not a flood; how many may still be, once known
        self._backlog_left: int | None = None
        self._announced = False

    # ------------------------------------------------------------------ hooks for subclasses
    def _datagram(self, data: bytes, t: float, sender: str) -> list[ControlEvent]:
        """Decode one datagram received at ``t`` (monotonic) from ``sender``."""
        raise NotImplementedError

    def _idle(self, t: float) -> list[ControlEvent]:
        """Called when a read times out; a stream that stopped may release its controls."""
        return []

    # ------------------------------------------------------------------ Device hooks
    def _open(self) -> None:
        self._close_handle()
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as err:
            sock.close()
            if err.errno in (98, 48):  # EADDRINUSE on Linux / macOS
                raise OSError(f"UDP port {self.port} on {self.host} is in use by another program; "
                              f"pick another port ({self.scheme}://{self.host}:PORT)") from err
            raise OSError(f"cannot listen on {self.host}:{self.port}: {err.strerror or err}") from err
        sock.setblocking(False)
        self.rcvbuf_granted = size_receive_buffer(sock, self.rcvbuf)
        if self.rcvbuf_granted < self.rcvbuf:
            self.warnings.warn("rcvbuf", f"receive buffer {self.rcvbuf_granted} bytes, not the {self.rcvbuf} "
                               f"asked: bursts may be dropped (raise it: sysctl -w net.core.rmem_max={self.rcvbuf})")
        self._ancillary = enable_drop_counter(sock)
        self._sock_drops = 0
        self._sock = sock
        self._backlog_left = None
        self.bound = sock.getsockname()[:2]
        if self.port == 0:
            # port 0 asks the system for a free port: say which, once, and keep it on a reopen
            # (the senders were told this one); before, nothing named it anywhere
            self.port = self.bound[1]
            self.description = self.description.replace(f"udp {self.host}:0", f"udp {self.host}:{self.port}")
            if not self.exposure:
                print(f"{self.spec}: listening for {self.WHAT} on UDP port {self.port} of {self.host}",
                      file=sys.stderr, flush=True)
        if self.exposure and not self._announced:
            self._announced = True
            self.exposure = exposure_text(self.spec, self.WHAT, self.parsed_host, self.bound[1], self.allow)
            print(self.exposure, file=sys.stderr, flush=True)

    def _close_handle(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            self._sock_drops = max(self._sock_drops, proc_drops(sock) or 0)
            self._drops_before += self._sock_drops
            self._sock_drops = 0
            sock.close()

    @property
    def drops(self) -> int:
        """Datagrams lost to bursts so far: dropped by the kernel when the receive buffer was full
        (its own counter, on Linux) plus those discarded over ``max_rate``."""
        return self._drops_before + self._sock_drops + self.discarded

    def _poll_drops(self, sock: socket.socket, now: float) -> None:
        """Drops after the last datagram are only in /proc: look there now and then."""
        if now - self._proc_read >= PROC_EVERY:
            self._proc_read = now
            seen = proc_drops(sock)
            if seen is not None and seen > self._sock_drops:
                self._sock_drops = seen

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        sock = self._sock
        if sock is None:
            raise OSError("socket not open")
        now = time.monotonic()
        if self._backlog_left is None:
            self._backlog_left = max(self._budget(), self.rcvbuf_granted // BACKLOG_BYTES)
        if self._window_count >= self._budget() and now - self._window_start < WINDOW:
            # over budget: leave the rest in (and to) the kernel until the window ends
            self._stop.wait(min(timeout, WINDOW - (now - self._window_start)))
            return ()
        ready, _, _ = select.select([sock, self._waker], [], [], timeout)
        if self._waker in ready:
            self._waker.drain()
        if sock not in ready:
            self._backlog_left = 0  # nothing waited: from now on every datagram is counted
            now = time.monotonic()
            self._poll_drops(sock, now)
            return self._idle(now)
        events: list[ControlEvent] = []
        for _ in range(BATCH):
            try:
                if self._ancillary:
                    n, anc, _flags, addr = sock.recvmsg_into([self._buf], ANC_SIZE, socket.MSG_TRUNC)
                    dropped = ancillary_drops(anc)
                    if dropped is not None and dropped > self._sock_drops:
                        self._sock_drops = dropped
                else:
                    n, addr = sock.recvfrom_into(self._buf, RECV_BUFFER, socket.MSG_TRUNC)
            except (BlockingIOError, InterruptedError):
                self._backlog_left = 0  # the queue is empty: whatever comes now is counted
                break
            t = time.monotonic()
            if self._backlog_left:
                self._backlog_left -= 1
            elif not self._count(t):
                self.discarded += 1
                break
            sender = str(addr[0])
            if not sender_allowed(sender, self.allow):
                self.refused += 1
                self.warnings.warn("refused", f"datagram from {sender} refused (not in allow=)")
                continue
            if n > self.max_size:
                self.warnings.warn("oversized", f"{n}-byte datagram from {sender} dropped (max_size={self.max_size})")
                continue
            self.datagrams += 1
            try:
                events += self._datagram(bytes(self._buf[:n]), t, sender)
            except Exception as err:  # a decoder bug must cost one datagram, never the reader
                self.warnings.warn("decode", f"datagram from {sender} could not be decoded: {err!r}")
        return coalesce(events)

    def _budget(self) -> int:
        return max(1, int(self.max_rate * WINDOW))

    def _count(self, t: float) -> bool:
        """Count one datagram against the flood budget; False when the window is spent. The backlog
        waiting when the reader starts is not counted: a Live Link phone streaming at 60 Hz while a
        cold show prepared its face for 45 s left 2,700 datagrams in the buffer, read at once."""
        if t - self._window_start >= WINDOW:
            self._window_start, self._window_count = t, 0
        self._window_count += 1
        if self._window_count > self._budget():
            self.warnings.warn("flood", f"more than {self.max_rate} datagrams/s; the excess is dropped")
            return False
        return True


def coalesce(events: list[ControlEvent]) -> list[ControlEvent]:
    """Keep only the last value of each absolute control within one batch (buttons and dials are
    all kept, in order): the live loop sees the newest position without the backlog."""
    if len(events) < 2:
        return events
    last: dict[str, int] = {}
    for i, e in enumerate(events):
        if e.kind == "axis":
            last[e.control] = i
    if len(last) == sum(1 for e in events if e.kind == "axis"):
        return events
    return [e for i, e in enumerate(events) if e.kind != "axis" or last[e.control] == i]
