"""``mock://SCRIPT`` — a deterministic scripted device, a complete backend used as the fake.

A script (TOML or JSON) is a timeline of events plus generators; it compiles to a sorted list of
timed items before playback, so two runs give the same events. ``speed = 0`` (or ``?speed=0``)
plays as fast as possible with event times equal to script times, and an injected ``clock``/``sleep``
pair drives real-time playback in tests without waiting. Script form::

    impersonate = "sgi"          # declare the control set of a named box (optional)
    counts_per_turn = 200        # dial resolution used for ``delta`` (default 200)
    speed = 1.0                  # 1 = real time, 2 = twice as fast, 0 = as fast as possible
    loop = false                 # start over after ``duration`` (default: last item time)
    [[controls]]                 # extra controls: name, kind, lo, hi, light
    [[events]]   t, control, value | delta (dials: counts)
    [[ramp]]     control, start, duration, from, to, rate        (dials: from/to in turns)
    [[sine]]     control, start, duration, freq, amplitude, offset, rate
    [[pattern]]  control, start, period, duty, count             (buttons/keys)
    [[status]]   t, status = "lost" | "connected"                (rehearse an unplug)

Inline form: ``mock://?impersonate=sgi&sine=dial0&buttons=button3&duration=2&rate=50``.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from devices.base import ControlInfo, Device
from devices.controlsets import DIAL_HI, DIAL_LO, control_set
from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from safefile import BadFile, load_json, load_toml, quote, read_text

Clock = Callable[[], float]
#: Samples one generator may produce (a typo in ``rate`` must not eat the memory).
MAX_SAMPLES = 100_000
MAX_SCRIPT_BYTES = 16 * 1024 * 1024
Sleep = Callable[[float], None]


@dataclass(frozen=True, slots=True)
class Item:
    """One scheduled happening: a control change, or a status change when ``status`` is set."""

    t: float
    control: str = ""
    value: float = 0.0
    delta: float | None = None
    raw: int | float | str | None = None
    status: str = ""


def _infer(name: str) -> ControlInfo:
    if name.startswith("key:"):
        return ControlInfo(name, "key")
    if name.startswith("button"):
        return ControlInfo(name, "button", 0.0, 1.0, True)
    if name.startswith(("dial", "knob", "jog", "encoder")):
        return ControlInfo(name, "dial", DIAL_LO, DIAL_HI)
    return ControlInfo(name, "axis", 0.0, 1.0)


#: the keys a script and each of its entries may have: a misspelt one (``[[rmp]]``, ``strat``) was
#: ignored, and the script played nothing of it without a word
SCRIPT_KEYS = frozenset({"impersonate", "counts_per_turn", "speed", "loop", "duration", "controls", "events",
                         "ramp", "sine", "pattern", "status"})
ENTRY_KEYS = {
    "controls": ("name", "kind", "lo", "hi", "light"),
    "events": ("t", "control", "value", "delta"),
    "ramp": ("control", "start", "duration", "from", "to", "rate"),
    "sine": ("control", "start", "duration", "freq", "amplitude", "offset", "rate"),
    "pattern": ("control", "start", "period", "duty", "count"),
    "status": ("t", "status"),
}


class Script:
    """A compiled script: declared controls and a sorted timeline."""

    def __init__(self, data: dict[str, Any], origin: str) -> None:
        self.origin = origin
        self._check_keys(data)
        self.counts_per_turn = int(data.get("counts_per_turn", 200))
        if self.counts_per_turn <= 0:
            raise self._error("counts_per_turn must be positive")
        self.speed = float(data.get("speed", 1.0))
        self.loop = bool(data.get("loop", False))
        self.strict = "impersonate" in data
        self.controls: dict[str, ControlInfo] = {}
        if self.strict:
            try:
                self.controls = {c.name: c for c in control_set(str(data["impersonate"]))}
            except KeyError as err:
                raise self._error(str(err.args[0])) from None
        for c in data.get("controls", []):
            info = ControlInfo(str(c["name"]), c.get("kind", "axis"), float(c.get("lo", 0.0)),
                               float(c.get("hi", 1.0)), bool(c.get("light", False)))
            if info.kind not in ("button", "dial", "axis", "key"):
                raise self._error(f"control {quote(info.name)}: unknown kind {quote(info.kind)}")
            self.controls[info.name] = info
        items: list[Item] = []
        for i, e in enumerate(data.get("events", [])):
            items.append(self._event(e, f"events[{i}]"))
        for i, g in enumerate(data.get("ramp", [])):
            items += self._ramp(g, f"ramp[{i}]")
        for i, g in enumerate(data.get("sine", [])):
            items += self._sine(g, f"sine[{i}]")
        for i, g in enumerate(data.get("pattern", [])):
            items += self._pattern(g, f"pattern[{i}]")
        for i, s in enumerate(data.get("status", [])):
            if s.get("status") not in ("lost", "connected"):
                raise self._error(f"status[{i}]: status must be 'lost' or 'connected'")
            items.append(Item(float(s["t"]), status=s["status"]))
        self.items = sorted(items, key=lambda it: it.t)  # stable: same-time items keep order
        last = self.items[-1].t if self.items else 0.0
        self.duration = float(data.get("duration", last))
        if self.loop and self.duration <= 0:
            raise self._error("a looping script needs a positive duration")

    def _error(self, msg: str) -> DeviceSpecError:
        return DeviceSpecError(f"{self.origin}: {msg}")

    def _check_keys(self, data: dict[str, Any]) -> None:
        unknown = sorted(str(k) for k in data if k not in SCRIPT_KEYS)
        if unknown:
            raise self._error(f"unknown key {quote(unknown[0])}; a script has "
                              f"{', '.join(sorted(SCRIPT_KEYS))} (docs/devices.md, mock://)")
        for table, allowed in ENTRY_KEYS.items():
            entries = data.get(table, [])
            if not isinstance(entries, list):
                raise self._error(f"{table} must be a list of tables ([[{table}]])")
            for i, entry in enumerate(entries):
                if not isinstance(entry, dict):
                    raise self._error(f"{table}[{i}] must be a table of keys")
                bad = sorted(str(k) for k in entry if k not in allowed)
                if bad:
                    raise self._error(f"{table}[{i}]: unknown key {quote(bad[0])}; expected {', '.join(allowed)}")

    def info(self, name: str, where: str) -> ControlInfo:
        """The control ``name``; declared on first use unless the script impersonates a box."""
        info = self.controls.get(name)
        if info is None:
            if self.strict:
                raise self._error(f"{where}: control {quote(name)} is not on the impersonated box")
            info = self.controls[name] = _infer(name)
        return info

    def _item(self, info: ControlInfo, t: float, value: float, where: str) -> Item:
        if not math.isfinite(value) or not info.lo - 1e-9 <= value <= info.hi + 1e-9:
            raise self._error(f"{where}: value {value:g} of {quote(info.name)} is outside {info.lo:g}..{info.hi:g}")
        if info.kind in ("button", "key") and value not in (0.0, 1.0):
            raise self._error(f"{where}: {quote(info.name)} takes 0 or 1, not {value:g}")
        return Item(t, info.name, value, None, value)

    def _dial(self, info: ControlInfo, t: float, counts: int) -> Item:
        return Item(t, info.name, counts / self.counts_per_turn, float(counts), counts)

    def _event(self, e: dict[str, Any], where: str) -> Item:
        try:
            t, name = float(e["t"]), str(e["control"])
        except (KeyError, TypeError, ValueError) as err:
            raise self._error(f"{where}: needs t and control ({quote(str(err))})") from None
        info = self.info(name, where)
        if info.kind == "dial":
            counts = int(e["delta"]) if "delta" in e else round(float(e.get("value", 0)) * self.counts_per_turn)
            if abs(counts) > self.counts_per_turn:
                raise self._error(f"{where}: one dial event may turn at most one turn")
            return self._dial(info, t, counts)
        return self._item(info, t, float(e.get("value", 1.0)), where)

    def _samples(self, g: dict[str, Any]) -> tuple[float, float, int]:
        start, duration, rate = float(g.get("start", 0)), float(g.get("duration", 1)), float(g.get("rate", 50))
        if not (math.isfinite(start) and 0 <= duration < math.inf and 0 < rate < math.inf):
            raise self._error("generator needs a finite start, duration >= 0 and rate > 0")
        n = max(1, int(round(duration * rate)))
        if n > MAX_SAMPLES:
            raise self._error(f"generator of {float(n):.3g} samples; at most {MAX_SAMPLES}")
        return start, duration, n

    def _curve(self, g: dict[str, Any], where: str, f: Callable[[float], float]) -> list[Item]:
        info = self.info(str(g["control"]), where)
        start, duration, n = self._samples(g)
        out: list[Item] = []
        if info.kind == "dial":  # f gives the position in turns; emit the count changes
            prev = round(f(0.0) * self.counts_per_turn)
            for k in range(1, n + 1):
                pos = round(f(duration * k / n) * self.counts_per_turn)
                step = max(-self.counts_per_turn, min(self.counts_per_turn, pos - prev))
                if step:
                    out.append(self._dial(info, start + duration * k / n, step))
                    prev += step
            return out
        for k in range(n + 1):
            out.append(self._item(info, start + duration * k / n, f(duration * k / n), where))
        return out

    def _ramp(self, g: dict[str, Any], where: str) -> list[Item]:
        a, b = float(g.get("from", 0.0)), float(g.get("to", 1.0))
        duration = float(g.get("duration", 1)) or 1.0
        return self._curve(g, where, lambda s: a + (b - a) * s / duration)

    def _sine(self, g: dict[str, Any], where: str) -> list[Item]:
        freq, amp, off = float(g.get("freq", 1.0)), float(g.get("amplitude", 0.5)), float(g.get("offset", 0.5))
        return self._curve(g, where, lambda s: off + amp * math.sin(2 * math.pi * freq * s))

    def _pattern(self, g: dict[str, Any], where: str) -> list[Item]:
        info = self.info(str(g["control"]), where)
        start, period = float(g.get("start", 0)), float(g.get("period", 0.5))
        duty, count = float(g.get("duty", 0.5)), int(g.get("count", 4))
        if not (0 < period < math.inf and 0 < duty < 1 and 0 <= count <= MAX_SAMPLES and math.isfinite(start)):
            raise self._error(f"{where}: needs period > 0, 0 < duty < 1 and 0 <= count <= {MAX_SAMPLES}")
        out = []
        for k in range(count):
            out.append(self._item(info, start + k * period, 1.0, where))
            out.append(self._item(info, start + k * period + duty * period, 0.0, where))
        return out


def load_script(location: str, query: dict[str, str], origin: str) -> Script:
    """Read a script file (TOML by default, JSON by suffix) or build one from inline options."""
    if location:
        path = Path(location)
        try:
            text = read_text(path, "mock script", MAX_SCRIPT_BYTES)
            if path.suffix.lower() == ".json":
                data = load_json(text, str(path), "mock script")
            else:
                data = load_toml(text, str(path), "mock script")
        except BadFile as err:
            raise DeviceSpecError(f"{origin}: the mock script is not valid: {err}") from err
        if not isinstance(data, dict):
            raise DeviceSpecError(f"{origin}: a mock script is a table of keys, not {type(data).__name__}")
    else:
        data = {}
        try:
            duration, rate = float(query.get("duration", 2.0)), float(query.get("rate", 50))
        except ValueError as err:
            raise DeviceSpecError(f"{origin}: duration and rate must be numbers") from err
        if "impersonate" in query:
            data["impersonate"] = query["impersonate"]
        for key, kind in (("sine", "sine"), ("ramp", "ramp"), ("buttons", "pattern")):
            if key in query:
                data.setdefault(kind, []).append(
                    {"control": query[key], "duration": duration, "rate": rate, "period": duration / 4,
                     "count": 4, "amplitude": 0.5 if kind == "sine" else None, "freq": 1.0 / duration}
                )
                data[kind][-1] = {k: v for k, v in data[kind][-1].items() if v is not None and k in ENTRY_KEYS[kind]}
        data["duration"] = duration
    for key in ("speed", "loop", "counts_per_turn"):
        if key in query:
            convert = {"speed": float, "counts_per_turn": int}.get(key, lambda v: v not in ("0", "false", "no"))
            try:
                data[key] = convert(query[key])
            except ValueError as err:
                raise DeviceSpecError(f"{origin}: option {key}={quote(query[key])} is not valid") from err
    return build_script(data, origin)


def build_script(data: Any, origin: str) -> Script:
    """Compile script data; any malformed entry becomes one DeviceSpecError naming the script."""
    if not isinstance(data, dict):
        raise DeviceSpecError(f"{origin}: a mock script is a table of keys, not {type(data).__name__}")
    try:
        return Script(data, origin)
    except DeviceSpecError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as err:
        raise DeviceSpecError(f"{origin}: bad mock script entry: {type(err).__name__}: {quote(str(err), 80)}") from err


class MockDevice(Device):
    """Plays a compiled ``Script``; see the module docstring for the script form."""

    scheme = "mock"
    FORM = "mock://SCRIPT.toml|.json or mock://?impersonate=NAME&sine=CTRL&ramp=CTRL&buttons=CTRL"
    OPTIONS = frozenset({"impersonate", "sine", "ramp", "buttons", "duration", "rate", "speed", "loop",
                         "counts_per_turn"})

    def __init__(self, spec: DeviceSpec, clock: Clock | None = None, sleep: Sleep | None = None,
                 **options: Any) -> None:
        super().__init__(spec, **options)
        self.script = load_script(spec.location, spec.query, spec.text)
        self.controls = list(self.script.controls.values())
        self.description = f"mock device playing {spec.location or 'inline generators'}"
        self._clock = clock or time.monotonic
        self._sleep = sleep
        self._index = 0
        self._offset = 0.0
        self._t0: float | None = None
        self._lost = False
        self.light_log: list[tuple[str, float]] = []
        self._done = threading.Event()

    @property
    def connected(self) -> bool:
        return self._connected and not self._lost

    @property
    def exhausted(self) -> bool:
        return self._done.is_set()

    def play_all(self) -> list[ControlEvent]:
        """Every control event of one pass, synchronously, with script times: for tests and
        headless recorded runs that need no thread at all."""
        return [self._make(it, it.t) for it in self.script.items if not it.status]

    def _make(self, it: Item, t: float) -> ControlEvent:
        info = self.script.controls[it.control]
        return ControlEvent(self.spec, it.control, info.kind, it.value, it.delta, it.raw, t)

    def _open(self) -> None:
        if self._closed:
            raise DeviceError(f"{self.spec}: closed")

    def _set_light(self, control: str, level: float) -> None:
        self.light_log.append((control, level))

    def _wake(self) -> None:
        self._stop.set()

    def _now(self) -> float:
        """Script time when playing as fast as possible, so a whole run is reproducible."""
        if self.script.speed > 0:
            return self._clock()
        return self.script.items[self._index - 1].t + self._offset if self._index else 0.0

    def _wait(self, seconds: float) -> None:
        if self._sleep is not None:
            self._sleep(seconds)
        else:
            self._stop.wait(seconds)

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        items = self.script.items
        if self._index >= len(items):
            if self.script.loop:
                self._index, self._offset = 0, self._offset + self.script.duration
            else:
                self._done.set()
                self._wait(timeout)
                return ()
        if self._t0 is None:
            self._t0 = self._clock()
        it = items[self._index]
        script_t = it.t + self._offset
        speed = self.script.speed
        if speed > 0:
            target = self._t0 + script_t / speed
            now = self._clock()
            if now < target:
                self._wait(min(timeout, target - now))
                return ()
            t = target
        else:
            t = script_t
        self._index += 1
        if it.status:
            self._lost = it.status == "lost"
            self._status(it.status, "scripted", t)
            return ()
        if self._lost:  # an unplugged box sends nothing
            return ()
        return (self._make(it, t),)
