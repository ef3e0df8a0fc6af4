"""The mapper: control events in, one array of channel values out per simulation tick.

Events are applied in arrival order at tick boundaries (`feed`), then `step(dt)` runs every
binding's filter chain once with the tick's dt and combines bindings per channel (max, clamped sum,
last wins). No clock is read here: the same events at the same ticks give the same values."""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from devices.events import ControlEvent, StatusEvent
from puppet.errors import ChannelError
from puppet.mapping import filters as F
from puppet.mapping.buttons import ButtonState, RadioGroup
from puppet.mapping.config import BindingSpec, FilterSpec, MappingSpec
from puppet.mapping.targets import Target, Vocabulary
from puppet.mapping.templates import expand_spec

PANIC_SECONDS = 0.6
#: A ring is not updated while its control moves and for this many ticks after its last input.
RING_HOLD_TICKS = 15


def build_filter(fs: FilterSpec) -> F.Filter:
    p = fs.params
    if fs.type == "range":
        return F.RangeMap(p["from"], p["to"], p["clamp"])
    if fs.type == "invert":
        return F.Invert()
    if fs.type == "curve":
        return F.Curve(p["gamma"], p["points"])
    if fs.type == "deadzone":
        return F.DeadZone(p["width"], p["center"])
    if fs.type == "smooth":
        return F.Smooth(p["rise"], p["fall"])
    if fs.type == "one_euro":
        return F.OneEuro(p["min_cutoff"], p["beta"], p["d_cutoff"])
    if fs.type == "slew":
        return F.Slew(p["rate"], p["fall"])
    raise ValueError(fs.type)


def device_matches(pattern: str | None, spec: str) -> bool:
    """A binding's `device` matches a spec exactly, by scheme (`sgi`), or as a glob."""
    if pattern is None:
        return True
    if pattern == spec:
        return True
    if "://" not in pattern and spec.split("://", 1)[0] == pattern:
        return True
    return fnmatch.fnmatchcase(spec, pattern)


@dataclass
class Binding:
    """Runtime state of one binding."""

    spec: BindingSpec
    target: Target | None
    chain: F.Chain
    button: ButtonState
    kind: str | None = None          # "absolute" | "relative" | "button", fixed at first event
    src: float = 0.0                 # source value in the binding's normalised space
    engaged: bool = True             # soft takeover: False until the control meets the value
    last_static: float | None = None
    out: float = 0.0                 # normalised output after the chain
    value: float = 0.0               # output in target units
    active: bool = False             # contributes this tick
    changed_tick: int = -1
    device: str | None = None        # spec of the device last seen driving it
    input_tick: int = -(1 << 30)     # tick of its last input event (rings hold still meanwhile)
    pickup_hit: bool = False         # soft takeover: an input event met or crossed the value
    stale: bool = False              # re-armed: where the control is is unknown until it moves
    declared: tuple[float, float] | None = None

    @property
    def pickup(self) -> bool:
        return self.spec.pickup if self.spec.pickup is not None else True

    def to_units(self, u: float) -> float:
        assert self.target is not None
        lo, hi = self.spec.dst_range or (self.target.lo, self.target.hi)
        return lo + u * (hi - lo)

    def to_norm(self, v: float) -> float:
        assert self.target is not None
        lo, hi = self.spec.dst_range or (self.target.lo, self.target.hi)
        return (v - lo) / (hi - lo) if hi != lo else 0.0


@dataclass
class MapperOutput:
    """What happened in one step besides the values: actions for the live loop."""

    panic: bool = False
    markers: list[str] = field(default_factory=list)


class Mapper:
    """Applies a MappingSpec to a face vocabulary."""

    def __init__(self, spec: MappingSpec, vocab: Vocabulary) -> None:
        self.spec, self.vocab = spec, vocab
        n = len(vocab.channels)
        self.defaults = np.array(vocab.defaults(), dtype=np.float64)
        self.lo = np.array([c.lo for c in vocab.channels], dtype=np.float64)
        self.hi = np.array([c.hi for c in vocab.channels], dtype=np.float64)
        self.values = self.defaults.copy()
        self.rules = []
        for c in vocab.channels:
            rule = spec.combine.get(c.name)
            if rule is None and c.name[-2:] in ("_l", "_r"):
                rule = spec.combine.get(c.name[:-2])
            if rule is None:
                rule = spec.default_combine or ("last" if c.kind in ("eyes", "age", "head") else "max")
            self.rules.append(rule)
        self.groups: dict[str, RadioGroup] = {}
        self.bindings: list[Binding] = []
        self.by_control: dict[str, list[Binding]] = {}
        self._add(spec)
        self.tick = 0
        self.status: dict[str, bool] = {}
        self.panic_left = 0.0
        self.panic_from = self.values.copy()
        self._pending = MapperOutput()
        self._lights: dict[tuple[str, str], bool | float] = {}
        self._n = n
        for b in self.bindings:
            self._reset_binding(b)

    def _add(self, spec: MappingSpec) -> list[Binding]:
        spec = expand_spec(spec, self.vocab)  # `{channel}`, `{au}`, `{expression}` families
        for g, allow in spec.radio_allow_none.items():
            self.groups.setdefault(g, RadioGroup(g, allow))
        added = []
        for bs in spec.bindings:
            target = None
            if bs.target is not None:
                try:
                    target = self.vocab.resolve(bs.target)
                except ChannelError as err:
                    raise spec.error(bs.path + ("target",), str(err)) from err
            group = None
            if bs.group is not None:
                group = self.groups.setdefault(bs.group, RadioGroup(bs.group))
            b = Binding(bs, target, F.Chain([build_filter(f) for f in bs.filters]),
                        ButtonState(bs.mode, group, bs.attack, bs.hold, bs.release))
            added.append(b)
        self.bindings += added
        for b in added:
            self.by_control.setdefault(b.spec.control, []).append(b)
        return added

    def add_spec(self, spec: MappingSpec) -> None:
        """Add the bindings of another map while running (a box plugged in mid-show); raises
        ConfigError before changing anything if a target is unknown."""
        Mapper(spec, self.vocab)  # check first: all or nothing
        for b in self._add(spec):
            self._reset_binding(b)
        self.rearm_pickup()  # the map changed: every absolute control picks up afresh

    # --- input -----------------------------------------------------------------------------------
    def declare_controls(self, device: str, controls: Iterable[object]) -> None:
        """Tell the mapper a device's declared control ranges (ControlInfo), used as the default
        input range of absolute controls."""
        for ci in controls:
            for b in self.by_control.get(getattr(ci, "name", ""), []):
                if device_matches(b.spec.device, device):
                    lo, hi = float(getattr(ci, "lo", 0.0)), float(getattr(ci, "hi", 1.0))
                    if hi != lo:
                        b.declared = (lo, hi)

    def feed(self, event: ControlEvent | StatusEvent) -> None:
        """Apply one event (at a tick boundary)."""
        if isinstance(event, StatusEvent):
            was = self.status.get(event.device)
            self.status[event.device] = event.status == "connected"
            if event.status == "connected" and was is False:  # back after an unplug: pots may have moved
                self.rearm_pickup(event.device)
            if event.status == "lost":  # an unplugged box cannot release what it held down
                for b in self.bindings:
                    if b.device == event.device and b.kind == "button" and b.button.down:
                        b.button.press(False)
            return
        self.status.setdefault(event.device, True)
        for b in self.by_control.get(event.control, ()):
            if device_matches(b.spec.device, event.device):
                b.device = event.device
                b.input_tick = self.tick
                self._apply(b, event)

    def _apply(self, b: Binding, ev: ControlEvent) -> None:
        kind = b.kind or b.spec.input or {"dial": "relative", "axis": "absolute"}.get(ev.kind, "button")
        b.kind = kind
        if kind == "button":
            down = ev.value > 0.5
            if b.spec.action is not None:
                if down and not b.button.down:
                    if b.spec.action == "panic":
                        self._pending.panic = True
                    else:
                        self._pending.markers.append(b.spec.label or f"{ev.control}")
                b.button.down = down
                return
            b.button.press(down)
        elif kind == "relative":
            self._resync_relative(b)
            if b.spec.encoding is not None:
                raw = ev.raw if isinstance(ev.raw, (int, float)) and not isinstance(ev.raw, bool) else ev.value
                turns = F.decode_relative(int(raw), b.spec.encoding, b.spec.bits) / b.spec.counts_per_turn
            else:
                turns = ev.value
            b.src = min(1.0, max(0.0, b.src + turns * b.spec.gain))
        else:
            lo, hi = b.spec.src_range or b.declared or (0.0, 1.0)
            b.src = min(1.0, max(0.0, (ev.value - lo) / (hi - lo)))
            b.stale = False
            if b.pickup and not b.engaged and b.target is not None:
                self._track_pickup(b)

    def _track_pickup(self, b: Binding) -> None:
        """Crossing detection per input event, not per tick: a fast move that passes the value
        between two ticks still picks it up."""
        here = b.chain.static_value(b.src)
        there = self._current_norm(b)
        prev, b.last_static = b.last_static, here
        if abs(here - there) <= b.spec.pickup_window or (prev is not None and (prev - there) * (here - there) <= 0.0):
            b.pickup_hit = True

    def _resync_relative(self, b: Binding) -> None:
        """A relative control nudges the value the face has now: if another binding moved the
        channel since this one last drove it, continue from there (no jump back)."""
        if b.target is None or not b.target.direct:
            return
        cur = float(self.values[b.target.channels[0][0]])
        if abs(cur - b.value) > 1e-9 and self.panic_left <= 0.0:
            b.src = min(1.0, max(0.0, b.to_norm(cur)))
            b.chain.reset(b.src)
            b.value = cur

    # --- per tick --------------------------------------------------------------------------------
    def step(self, dt: float) -> np.ndarray:
        """Advance every binding by dt and return the channel values (a new array)."""
        self.tick += 1
        contrib: dict[int, list[tuple[int, float, int]]] = {}  # only the channels something drives
        for idx, b in enumerate(self.bindings):
            if b.target is None or b.kind is None:
                continue  # never touched: at rest by construction (a template map has a hundred)
            self._step_binding(b, dt)
            if not b.active:
                continue
            t = b.target
            for ch, w in t.channels:
                contrib.setdefault(ch, []).append(
                    (b.changed_tick * 4096 + idx, b.value if t.direct else b.value * w, idx))
        values = self.defaults.copy()
        for ch, cs in contrib.items():
            rule = self.rules[ch]
            if rule == "max":
                values[ch] = max(v for _, v, _ in cs)
            elif rule == "sum":
                direct = [v for _, v, i in cs if self.bindings[i].target.direct]  # type: ignore[union-attr]
                weights = [v for _, v, i in cs if not self.bindings[i].target.direct]  # type: ignore[union-attr]
                base = sum(direct) if direct else self.defaults[ch]
                values[ch] = base + sum(weights)
            else:
                values[ch] = max(cs)[1]
        np.clip(values, self.lo, self.hi, out=values)
        if self._pending.panic and self.panic_left <= 0.0:
            self.panic_left = PANIC_SECONDS
            self.panic_from = self.values.copy()
            self._reset_all()
        if self.panic_left > 0.0:
            self.panic_left = max(0.0, self.panic_left - dt)
            s = self.panic_left / PANIC_SECONDS
            ease = s * s * (3.0 - 2.0 * s)  # smoothstep: no jolt at either end
            values = self.defaults + (self.panic_from - self.defaults) * ease
            if self.panic_left == 0.0:
                self._reset_all()
        self.values = values
        self._pending.panic = False
        return values.copy()

    def _step_binding(self, b: Binding, dt: float) -> None:
        assert b.target is not None
        if b.kind == "button":
            x = b.button.level(dt)
        else:
            x = b.src
            if (b.chain.settled_at(x, dt) and b.active == (b.kind is not None)
                    and not (b.kind == "absolute" and b.pickup and not b.engaged)):
                return  # a control at rest whose filters have settled: this step changes nothing
        if b.kind == "absolute" and b.pickup and not b.engaged:
            if b.stale:
                return  # re-armed: wait for the control to move before comparing
            here = b.chain.static_value(x)
            there = self._current_norm(b)
            prev = b.last_static
            b.last_static = here
            crossed = b.pickup_hit or (prev is not None and (prev - there) * (here - there) <= 0.0)
            if abs(here - there) <= b.spec.pickup_window or crossed:
                b.engaged = True
                b.pickup_hit = False
                b.chain.reset(there)
            else:
                return
        u = b.chain.step(x, dt)
        v = b.to_units(u)
        if v != b.value or b.changed_tick < 0:
            b.changed_tick = self.tick
        b.out, b.value = u, v
        if b.kind == "button" and b.spec.action is None:
            b.active = u > 1e-9 or b.button.is_on()
        else:
            b.active = b.kind is not None  # a control contributes once it has been touched

    def _current_norm(self, b: Binding) -> float:
        assert b.target is not None
        if b.target.direct:
            return b.to_norm(float(self.values[b.target.channels[0][0]]))
        return b.out

    def _reset_binding(self, b: Binding) -> None:
        if b.target is None:
            return
        start = b.to_norm(b.target.default) if b.target.direct else 0.0
        start = min(1.0, max(0.0, start))
        b.button.reset()
        b.src, b.out, b.value = start, start, b.to_units(start)
        b.chain.reset(start)
        b.engaged = not (b.kind in (None, "absolute") and b.pickup)
        b.last_static = None
        b.pickup_hit = False
        b.active = False

    def _reset_all(self) -> None:
        for g in self.groups.values():
            g.active = None
        for b in self.bindings:
            self._reset_binding(b)

    # --- actions and feedback --------------------------------------------------------------------
    def panic(self) -> None:
        """Ease every channel back to neutral over PANIC_SECONDS and reset the bindings."""
        self._pending.panic = True

    def take_markers(self) -> list[str]:
        out, self._pending.markers = self._pending.markers, []
        return out

    def light_changes(self) -> list[tuple[str, str, bool | float]]:
        """(device, control, state) for lights whose state changed since the last call: a button's
        light on/off (bool), and an encoder's or fader's ring (a 0..1 level, in 1/127 steps) showing
        the value of the channel it drives, so it follows other bindings and panic too. A ring is
        left alone while its control is being moved and for RING_HOLD_TICKS after: what it would show
        then is the input itself, and a box whose ring also sets the encoder would fight the hand.
        A device without such a light ignores the call."""
        out: list[tuple[str, str, bool | float]] = []
        rings: set[tuple[str, str]] = set()
        for b in self.bindings:
            if b.device is None or b.spec.action is not None:
                continue
            key = (b.device, b.spec.control)
            if b.kind in ("relative", "absolute"):
                if key in rings:
                    continue  # a control driving several targets: its first binding's shows on the ring
                rings.add(key)
                if b.spec.light is False or b.target is None or self.tick - b.input_tick < RING_HOLD_TICKS:
                    continue
                level = round(min(1.0, max(0.0, self._current_norm(b))) * 127) / 127
                if self._lights.get(key) != level:
                    self._lights[key] = level
                    out.append((b.device, b.spec.control, level))
                continue
            want = b.spec.light if b.spec.light is not None else b.spec.mode in ("toggle", "radio", "trigger")
            if not want:
                continue
            on = b.button.is_on()
            if self._lights.get(key) != on:
                self._lights[key] = on
                out.append((b.device, b.spec.control, on))
        return out

    def rearm_pickup(self, device: str | None = None) -> None:
        """Absolute controls (of `device`, or all) wait for pickup again: after a map change, or a
        box that was unplugged (its faders may have moved meanwhile). Crossing detection starts
        afresh, so the first move after this cannot jump over the value either."""
        for b in self.bindings:
            if b.kind in (None, "absolute") and b.pickup and (device is None or b.device == device):
                b.engaged = False
                b.last_static = None
                b.pickup_hit = False
                b.stale = True

    def hud_lines(self, limit: int = 24) -> list[str]:
        """One line per binding: control -> target = value, and its device as connected/lost."""
        lines = []
        for b in self.bindings[:limit]:
            dev = b.device
            if dev is None:
                state = "waiting"
            else:
                state = "connected" if self.status.get(dev, True) else "LOST"
            what = b.spec.target or f"action:{b.spec.action}"
            pick = " (move to pick up)" if b.kind == "absolute" and not b.engaged else ""
            val = "" if b.target is None else f" = {b.value:.2f}"
            lines.append(f"{b.spec.label or b.spec.control:>10} -> {what}{val} [{state}]{pick}")
        return lines

    def binding_status(self) -> list[tuple[str, str, str]]:
        """(control, target, 'connected' | 'lost' | 'waiting') for every binding."""
        out = []
        for b in self.bindings:
            st = "waiting" if b.device is None else ("connected" if self.status.get(b.device, True) else "lost")
            out.append((b.spec.control, b.spec.target or f"action:{b.spec.action}", st))
        return out

