"""The page shows how loud an audio input hears (the level beside its status)."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace

import numpy as np

from devices import parse_spec
from devices.audio.device import AudioDevice
from puppet.panel.device import PanelDevice


def test_the_state_carries_the_level_of_an_audio_input_only() -> None:
    page = PanelDevice(parse_spec("panel://127.0.0.1:0"))
    mic = AudioDevice(parse_spec("audio://voice?api=jack"))  # not opened: its level is known all the same
    mic.values = (0.42, 0.3, 0.0, 0.0, 0.0, 0.0)
    core = SimpleNamespace(values=np.zeros(3), tick_count=10, rate=60.0, frames=10,
                           latency=SimpleNamespace(samples=deque()), markers=[],
                           mapper=SimpleNamespace(status={mic.spec: True}))
    page.watch(core, [mic, page])
    rows = page._state()["devices"]
    assert rows[0] == ["audio://voice?api=jack", True, None, 0.42]  # [spec, connected, drops, level]
    assert len(rows[1]) == 3  # the page itself has no level
