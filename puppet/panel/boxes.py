"""Control boxes in the editor: re-recording with a dial instead of a slider.

`BoxFeed` opens the given devices, maps them (their default maps, or a mapping file) and steps the
mapper at the 60 Hz tick in its own thread, like the live loop does, but with no face: it only
keeps the latest channel values and which channels a touched binding drives. The editor's
WebSocket sends them to the page, where an armed graph follows the box while it is touched."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

TICK = 1.0 / 60.0


class BoxFeed:
    def __init__(self, specs: Sequence[str], vocab: Any, map_path: str | None = None) -> None:
        import devices
        from puppet.live import build_mapping
        from puppet.mapping import Mapper

        # first: close() needs them (a map that cannot be read closes the boxes opened; close()
        # met no _stop and an AttributeError traceback hid the map's one line)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="editor boxes", daemon=True)
        self.devs: list[Any] = []
        try:
            for s in specs:
                self.devs.append(devices.open_device(s))
            spec = build_mapping(vocab, map_path, [(d.spec, d.description) for d in self.devs])
            self.mapper = Mapper(spec, vocab)
        except Exception:
            self.close()
            raise
        for d in self.devs:
            self.mapper.declare_controls(d.spec, d.controls)
        self.names = [c.name for c in vocab.channels]
        self.queue = devices.EventQueue()
        self.values = np.array(self.mapper.values, copy=True)
        self.driven: list[str] = []
        self.status: dict[str, bool] = {}

    def start(self) -> None:
        for d in self.devs:
            d.add_listener(self.queue)
            d.start()
        self._thread.start()

    def _run(self) -> None:
        nxt = time.monotonic()
        while not self._stop.is_set():
            for ev in self.queue.drain():
                self.mapper.feed(ev)
            self.values = self.mapper.step(TICK)
            self.mapper.take_markers()
            driven = set()
            for b in self.mapper.bindings:
                if b.active and b.target is not None and b.kind is not None:
                    driven.update(self.names[i] for i, _ in b.target.channels)
            self.driven = sorted(driven)
            self.status = {d.spec: bool(self.mapper.status.get(d.spec, d.connected)) for d in self.devs}
            nxt += TICK
            delay = nxt - time.monotonic()
            if delay < -4 * TICK:
                nxt = time.monotonic()
            elif delay > 0:
                self._stop.wait(delay)

    def state(self) -> dict[str, Any]:
        return {"t": "box", "values": [round(float(v), 6) for v in self.values], "driven": list(self.driven),
                "devices": [[k, v] for k, v in self.status.items()]}

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2)
        for d in self.devs:
            try:
                d.close()
            except Exception:
                pass
