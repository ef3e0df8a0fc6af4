"""Button modes: how a press/release stream becomes a level in 0..1.

Presses are applied at tick boundaries in arrival order; the envelope of a trigger advances by the
tick's dt, so button behaviour replays exactly."""

from __future__ import annotations

from dataclasses import dataclass

BUTTON_MODES = ("momentary", "toggle", "radio", "trigger")
EPS = 1e-9  # summed tick dts fall a hair short of a phase length


@dataclass
class RadioGroup:
    """Buttons of which at most one is on; `allow_none` lets a second press turn it off."""

    name: str
    allow_none: bool = True
    active: object | None = None


@dataclass
class ButtonState:
    """The state of one button binding. `press(down)` takes a 0/1 edge; `level(dt)` is called
    once per tick and returns the current level (0..1)."""

    mode: str = "momentary"
    group: RadioGroup | None = None
    attack: float = 0.08
    hold: float = 0.0
    release: float = 0.15
    down: bool = False
    on: bool = False
    # trigger envelope: phase in "idle" | "attack" | "hold" | "release"; t = seconds into phase
    phase: str = "idle"
    t: float = 0.0
    env: float = 0.0
    env_start: float = 0.0
    _tapped: bool = False

    def press(self, down: bool) -> None:
        """Apply an edge (at a tick boundary). A press and release within one tick still shows
        a momentary button for that tick."""
        self._tapped |= down
        self._edge(down)

    def _edge(self, down: bool) -> None:
        was = self.down
        self.down = down
        if self.mode == "momentary":
            return
        if not down or was:
            return  # the other modes act on presses only; repeated "down" is a repeat
        if self.mode == "toggle":
            self.on = not self.on
        elif self.mode == "radio":
            g = self.group
            if g is None:
                self.on = not self.on
            elif g.active is self:
                if g.allow_none:
                    g.active = None
            else:
                g.active = self
        elif self.mode == "trigger":
            # retrigger from wherever the envelope is, so a second press never jumps
            self.phase, self.t, self.env_start = "attack", 0.0, self.env

    def is_on(self) -> bool:
        """Whether the button holds its target on (lights show this)."""
        if self.mode == "momentary":
            return self.down
        if self.mode == "radio" and self.group is not None:
            return self.group.active is self
        if self.mode == "trigger":
            return self.phase != "idle"
        return self.on

    def level(self, dt: float) -> float:
        """The level for this tick; advances the trigger envelope by dt."""
        pressed_this_tick, self._tapped = self._tapped, False
        if self.mode == "momentary":
            # a tap shorter than a tick still shows for one tick
            return 1.0 if (self.down or pressed_this_tick) else 0.0
        if self.mode == "trigger":
            return self._advance(dt)
        return 1.0 if self.is_on() else 0.0

    def _advance(self, dt: float) -> float:
        if self.phase == "idle":
            self.env = 0.0
            return 0.0
        self.t += dt
        if self.phase == "attack":
            if self.t >= self.attack - EPS:
                self.phase, self.t = "hold", max(0.0, self.t - self.attack)
            else:
                self.env = self.env_start + (1.0 - self.env_start) * (self.t / self.attack)
                return self.env
        if self.phase == "hold":
            if self.t >= self.hold - EPS:
                self.phase, self.t = "release", max(0.0, self.t - self.hold)
            else:
                self.env = 1.0
                return 1.0
        if self.phase == "release":
            if self.t >= self.release - EPS:
                self.phase, self.t, self.env = "idle", 0.0, 0.0
                return 0.0
            self.env = 1.0 - self.t / self.release
            return self.env
        return self.env

    def reset(self) -> None:
        """Back to off (the panic key): toggles off, radio groups cleared, envelopes stopped."""
        self.on, self.phase, self.t, self.env = False, "idle", 0.0, 0.0
        self._tapped = False
        if self.group is not None and self.group.active is self:
            self.group.active = None
