"""Receive buffers sized for bursts, and the kernel's own count of datagrams it dropped.

A UDP socket's default receive buffer (``net.core.rmem_default``, 208 KiB on Linux) holds only
about 200 small datagrams, since each costs the kernel ~1 KiB of bookkeeping; a phone or a face
tracker that sends a burst while the reader is busy overflows it and the kernel drops the rest,
silently. So listeners ask for a larger buffer and read back what was granted, and count drops
from the kernel itself: on Linux the ``SO_RXQ_OVFL`` ancillary datum carried by each received
datagram (the socket's drop total when that datagram was queued) and, for drops after the last
datagram or where that option is missing, the ``drops`` column of /proc/net/udp for the socket's
inode. Elsewhere the count is unknown (None)."""

from __future__ import annotations

import os
import socket
import struct
import sys

#: What a listener asks for by default: ~4000 small datagrams, several seconds of any face stream.
DEFAULT_RCVBUF = 4 * 1024 * 1024
#: Linux's option numbers (asm-generic; Python's socket module does not name them).
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)
LINUX = sys.platform.startswith("linux")
#: Room for the drop counter's ancillary datum in recvmsg.
ANC_SIZE = socket.CMSG_SPACE(4) if hasattr(socket, "CMSG_SPACE") else 0


def size_receive_buffer(sock: socket.socket, want: int) -> int:
    """Ask for a `want`-byte receive buffer; returns the size the kernel reports granted (Linux
    reports twice the request, the doubling being its bookkeeping). Beyond net.core.rmem_max the
    request is capped, unless the process may force it (CAP_NET_ADMIN)."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, want)
    except OSError:
        pass
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    if LINUX and granted < want:
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, want)
            granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        except OSError:  # not permitted: keep what rmem_max allowed
            pass
    return int(granted)


def enable_drop_counter(sock: socket.socket) -> bool:
    """Have each received datagram carry the socket's drop total (Linux); True when it will."""
    if not LINUX or not hasattr(sock, "recvmsg_into"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        return bool(sock.getsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL))
    except OSError:
        return False


def ancillary_drops(ancdata: list[tuple[int, int, bytes]]) -> int | None:
    """The drop total in a datagram's ancillary data, if it carries one (it is left out while 0)."""
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(data) >= 4:
            return int(struct.unpack("=I", data[:4])[0])
    return None


def proc_drops(sock: socket.socket) -> int | None:
    """The drops column of /proc/net/udp (or udp6) for this socket's inode; None where unknown."""
    if not LINUX:
        return None
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except (OSError, ValueError):
        return None
    name = "udp6" if sock.family == socket.AF_INET6 else "udp"
    try:
        with open(f"/proc/net/{name}", encoding="ascii") as fh:
            next(fh, None)  # the column names
            for line in fh:
                cols = line.split()
                if len(cols) >= 13 and cols[9] == inode:
                    return int(cols[12])
    except (OSError, ValueError):
        return None
    return None
