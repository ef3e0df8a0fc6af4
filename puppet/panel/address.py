"""Where the page is served, without the web server: the default port and whether a host is this
machine's loopback. The panel device checks its address when it opens, before the first tick, and
must not import the web server (aiohttp) to do so: a show's start stays free of it."""

from __future__ import annotations

import ipaddress

DEFAULT_PORT = 8765


def is_loopback(host: str) -> bool:
    """True for localhost, the empty host (the default), 127.0.0.0/8 and ::1 (bracketed or not)."""
    if host in ("localhost", ""):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
