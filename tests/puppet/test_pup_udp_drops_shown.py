"""What a network listener lost to a burst reaches the performer: the HUD's device line and the
device list the page receives carry the count, read from a real overflowed 127.0.0.1 socket."""

from __future__ import annotations

import socket
import sys
import time
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "devices"))

from netdev import osc_message  # noqa: E402

import devices  # noqa: E402
from puppet.live import live_hud  # noqa: E402


def _flooded_listener() -> devices.Device:
    dev = devices.open_device("osc://127.0.0.1:0?rcvbuf=65536&max_rate=10000000")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for _ in range(2000):
        tx.sendto(osc_message("/face/channel/jaw", 0.5), ("127.0.0.1", dev.bound[1]))  # type: ignore[attr-defined]
    tx.close()
    dev.start()
    deadline = time.monotonic() + 5
    while dev.datagrams + (dev.drops or 0) < 2000 and time.monotonic() < deadline:  # type: ignore[attr-defined]
        time.sleep(0.05)
    return dev


def test_drops_reach_the_hud_and_the_page_state() -> None:
    osc = _flooded_listener()
    page = devices.open_device("panel://127.0.0.1:0")
    kb = devices.open_device("keyboard://")
    try:
        drops = osc.drops
        assert drops and drops > 0
        mapper = SimpleNamespace(status={}, bindings=[])
        core = SimpleNamespace(mapper=mapper, latency=SimpleNamespace(percentile=lambda q: None, samples=deque()),
                               face=SimpleNamespace(model=SimpleNamespace(channels=[])), values=np.zeros(0),
                               tick_count=0, rate=60.0, frames=0, markers=[])
        hud = live_hud(core, [osc, kb], keymap=False)  # type: ignore[arg-type]
        assert hud.devices[0] == (osc.spec, True, drops)
        assert hud.devices[1] == (kb.spec, True)  # a device that cannot drop says nothing about it
        page.watch(core, [osc, kb, page])  # type: ignore[attr-defined]
        listed = {d[0]: d for d in page._state()["devices"]}  # type: ignore[attr-defined]
        assert listed[osc.spec][2] == drops and listed[kb.spec][2] is None
    finally:
        for d in (osc, page, kb):
            d.close()
