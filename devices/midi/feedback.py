"""Host -> controller feedback shared by the MIDI backends: button LEDs and encoder rings.

What the live loop asks for (``set_light(control, level)``) becomes the profile's message and is
sent by the device's reader thread, so a caller never blocks on a slow port. Each control's light
is de-duplicated (the same bytes are not sent twice) and rate-limited (at most one message per
``interval``; the newest level is sent when the interval ends, so the last word always arrives).
Lights are only ever sent where the profile declares them and only from what the application
asks, never from input; and input that repeats what was just sent (a box with MIDI Thru on, or a
patchbay loop) is recognised as an echo and dropped, so no feedback loop can form.
"""

from __future__ import annotations

import threading

from devices.midi.profile import MidiProfile
from devices.warn import WarningCounter

#: Shortest time between two messages to one light or ring (rings follow a fast fader at 50 Hz).
LIGHT_INTERVAL = 0.02
#: An input message equal to one sent this recently is our own message coming back (a MIDI Thru
#: echo takes a few ms; a hand pressing the same button again takes well over 0.1 s).
ECHO_WINDOW = 0.1


class Feedback:
    """Pending lights, what was last sent, and recent output for echo detection."""

    def __init__(self, profile: MidiProfile, warnings: WarningCounter, interval: float = LIGHT_INTERVAL) -> None:
        self.interval = interval
        self.warnings = warnings
        self._defs = {cd.name: cd for cd in profile.controls if cd.light is not None or cd.ring is not None}
        self._pending: dict[str, tuple[int, ...]] = {}
        self._sent: dict[str, tuple[int, ...]] = {}
        self._when: dict[str, float] = {}
        self._recent: dict[tuple[int, ...], float] = {}
        self.echoes = 0
        self._lock = threading.Lock()  # requests come from the live loop, sending from the reader

    def request(self, control: str, level: float) -> bool:
        """Queue the message that shows ``level`` on ``control``; False if it has no light."""
        cd = self._defs.get(control)
        if cd is None:
            return False
        msg = cd.light.button(level) if cd.light is not None else cd.ring.ring_value(level)  # type: ignore[union-attr]
        with self._lock:
            self._pending[control] = msg
        return True

    def forget_sent(self) -> None:
        """After a (re)open the box shows nothing we know of: send every light again."""
        with self._lock:
            self._sent.clear()
            self._when.clear()

    def due(self, now: float) -> tuple[list[tuple[int, ...]], float | None]:
        """Messages to send now, and when the next held-back one is due (None: nothing waits)."""
        with self._lock:
            return self._due(now)

    def _due(self, now: float) -> tuple[list[tuple[int, ...]], float | None]:
        out: list[tuple[int, ...]] = []
        nxt: float | None = None
        for control, msg in list(self._pending.items()):
            if self._sent.get(control) == msg:
                del self._pending[control]  # already showing: de-duplicated
                continue
            ready = self._when.get(control, -1e9) + self.interval
            if now < ready:
                nxt = ready if nxt is None else min(nxt, ready)
                continue
            del self._pending[control]
            self._sent[control] = msg
            self._when[control] = now
            self._recent[msg] = now
            out.append(msg)
        if len(self._recent) > 512:
            self._recent = {m: w for m, w in self._recent.items() if now - w < ECHO_WINDOW}
        return out, nxt

    def is_echo(self, msg: tuple[int, ...], now: float) -> bool:
        """True for input that repeats a message sent within ECHO_WINDOW (dropped, counted)."""
        with self._lock:
            when = self._recent.get(msg)
            if when is None or now - when > ECHO_WINDOW:
                return False
            del self._recent[msg]
        self.echoes += 1
        self.warnings.warn("echo", "input repeats the lights sent to the box (MIDI Thru on, or a loop "
                           "in the MIDI routing?); dropped")
        return True
