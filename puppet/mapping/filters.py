"""Per-binding signal filters. Each runs once per simulation tick with that tick's dt, so a live run
and its replay see exactly the same numbers; none of them reads a clock.

Values travel through a chain in the binding's normalised space: 0..1 spans the target's range
(a channel's [lo, hi], or 0..1 weight for AUs and expressions)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol


class Filter(Protocol):
    """One stage: `step(x, dt)` returns the filtered value; `reset(x)` jumps the state to x;
    `state()` is everything `step` reads besides its arguments and parameters (None: memoryless)."""

    def step(self, x: float, dt: float) -> float: ...

    def reset(self, x: float) -> None: ...

    def state(self) -> object: ...


def _clamp(x: float, lo: float = 0.0, hi: float = 1.0) -> float:
    return lo if x < lo else hi if x > hi else x


class _Memoryless:
    """A stage without state: its output depends on its input only."""

    def reset(self, x: float) -> None:
        pass

    def state(self) -> object:
        return None


class _Follower:
    """A stage whose whole state is its last output `y` (None until the first sample, which passes
    through); `_next(x, dt)` is the stage's rule for the next output."""

    y: float | None

    def step(self, x: float, dt: float) -> float:
        if self.y is None:
            self.y = x
            return x
        self.y = self._next(self.y, x, dt)
        return self.y

    def _next(self, y: float, x: float, dt: float) -> float:
        raise NotImplementedError

    def reset(self, x: float) -> None:
        self.y = x

    def state(self) -> object:
        return self.y


@dataclass
class RangeMap(_Memoryless):
    """Linear remap of [src_lo, src_hi] to [dst_lo, dst_hi]; `clamp` keeps the output inside."""

    src: tuple[float, float] = (0.0, 1.0)
    dst: tuple[float, float] = (0.0, 1.0)
    clamp: bool = True

    def step(self, x: float, dt: float) -> float:
        s0, s1 = self.src
        d0, d1 = self.dst
        u = (x - s0) / (s1 - s0) if s1 != s0 else 0.0
        if self.clamp:
            u = _clamp(u)
        return d0 + u * (d1 - d0)


@dataclass
class Invert(_Memoryless):
    """1 - x: a dial that should close what it opens."""

    def step(self, x: float, dt: float) -> float:
        return 1.0 - x


@dataclass
class Curve(_Memoryless):
    """Response curve: x**gamma, or a piecewise-linear curve through (x, y) points sorted by x.
    Gamma > 1 gives fine control near zero, where small muscle activations live."""

    gamma: float | None = None
    points: Sequence[tuple[float, float]] = ()

    def step(self, x: float, dt: float) -> float:
        if self.points:
            pts = self.points
            if x <= pts[0][0]:
                return pts[0][1]
            for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
                if x <= x1:
                    return y0 + (y1 - y0) * ((x - x0) / (x1 - x0) if x1 != x0 else 1.0)
            return pts[-1][1]
        g = 1.0 if self.gamma is None else self.gamma
        return math.copysign(abs(x) ** g, x)


@dataclass
class DeadZone(_Memoryless):
    """Zero within `width` of `center`, then rescaled so the output still reaches 0 and 1 at the
    ends: no jump at the edge of the zone. Kills the jitter of a worn pot at rest."""

    width: float = 0.05
    center: float = 0.0

    def step(self, x: float, dt: float) -> float:
        c, w = self.center, self.width
        if abs(x - c) <= w:
            return c
        if x > c:
            span = (1.0 - c) - w
            return c + (x - c - w) * ((1.0 - c) / span) if span > 0 else 1.0
        span = c - w
        return c - (c - x - w) * (c / span) if span > 0 else 0.0


@dataclass
class Smooth(_Follower):
    """First-order low-pass with separate time constants for rising and falling values (seconds):
    a muscle can snap on and relax slowly, or the reverse. 0 means no smoothing that way."""

    rise: float = 0.05
    fall: float = 0.05
    y: float | None = None

    def _next(self, y: float, x: float, dt: float) -> float:
        tau = self.rise if x > y else self.fall
        a = 1.0 if tau <= 0.0 else 1.0 - math.exp(-dt / tau)
        return y + a * (x - y)


@dataclass
class OneEuro:
    """One-Euro filter (Casiez, Roussel & Vogel, CHI 2012): little lag when the control moves fast,
    strong smoothing when it is nearly still. min_cutoff in Hz, beta the speed coefficient,
    d_cutoff the cutoff for the derivative estimate."""

    min_cutoff: float = 1.0
    beta: float = 0.0
    d_cutoff: float = 1.0
    x_prev: float | None = None
    dx_prev: float = 0.0

    @staticmethod
    def _alpha(cutoff: float, dt: float) -> float:
        r = 2.0 * math.pi * cutoff * dt
        return r / (r + 1.0)

    def step(self, x: float, dt: float) -> float:
        if self.x_prev is None or dt <= 0.0:
            self.x_prev = x
            return x
        dx = (x - self.x_prev) / dt
        a_d = self._alpha(self.d_cutoff, dt)
        dx_hat = self.dx_prev + a_d * (dx - self.dx_prev)
        cutoff = self.min_cutoff + self.beta * abs(dx_hat)
        a = self._alpha(cutoff, dt)
        y = self.x_prev + a * (x - self.x_prev)
        self.x_prev, self.dx_prev = y, dx_hat
        return y

    def reset(self, x: float) -> None:
        self.x_prev, self.dx_prev = x, 0.0

    def state(self) -> object:
        return (self.x_prev, self.dx_prev)


@dataclass
class Slew(_Follower):
    """Limits the rate of change to `rate` full ranges per second (`fall` if given for decreasing
    values): a twitchy dial cannot make the face snap."""

    rate: float = 4.0
    fall: float | None = None
    y: float | None = None

    def _next(self, y: float, x: float, dt: float) -> float:
        up = self.rate * dt
        down = (self.rate if self.fall is None else self.fall) * dt
        d = x - y
        return y + (up if d > up else -down if d < -down else d)


@dataclass
class Chain:
    """Filters applied in the order written in the mapping file.

    A chain that has settled is not run again: when a step with input x and dt left every stage's
    state as it was, the same x and dt can only give the same output again (each stage is a
    function of its state and arguments), so until the input, dt or a reset changes, `step`
    returns that output without running the stages. Most controls sit still most of the time."""

    stages: list[Filter] = field(default_factory=list)
    _settled: tuple[float, float, float] | None = field(default=None, repr=False, compare=False)

    def settled_at(self, x: float, dt: float) -> bool:
        """True when `step(x, dt)` would return the last output and change nothing."""
        done = self._settled
        return done is not None and done[0] == x and done[1] == dt

    def step(self, x: float, dt: float) -> float:
        done = self._settled
        if done is not None and done[0] == x and done[1] == dt:
            return done[2]
        before = [f.state() for f in self.stages]
        y = x
        for f in self.stages:
            y = f.step(y, dt)
        settled = all(f.state() == b for f, b in zip(self.stages, before))
        self._settled = (x, dt, y) if settled else None
        return y

    def reset(self, x: float) -> None:
        self._settled = None
        for f in self.stages:
            f.reset(x)
            x = f.step(x, 0.0)

    def static_value(self, x: float) -> float:
        """The value with only the memoryless stages applied: where the control 'points', used
        by soft takeover to compare the physical position with the channel's value."""
        for f in self.stages:
            if isinstance(f, _Memoryless):
                x = f.step(x, 0.0)
        return x


# --- relative encoders ---------------------------------------------------------------------------

ENCODINGS = ("twos_complement", "sign_magnitude", "offset64", "binary")


def decode_relative(raw: int, encoding: str, bits: int = 7) -> int:
    """Signed step count from one byte of a relative encoder, in the common encodings:
    two's complement (1 = +1, 127 = -1), sign-magnitude (bit 6 = minus: 65 = -1), offset-64 /
    binary offset (64 = 0, 65 = +1, 63 = -1) and 'binary' (only direction: 0..63 up, 64..127 down;
    some boxes send 1/127, we read the sign). `bits` is the width of the field (7 for MIDI-style)."""
    full = 1 << bits
    half = full >> 1
    raw = int(raw) & (full - 1)
    if encoding == "twos_complement":
        return raw - full if raw >= half else raw
    if encoding == "sign_magnitude":
        return -(raw & (half - 1)) if raw & half else raw
    if encoding == "offset64":
        return raw - half
    if encoding == "binary":
        if raw == 0:
            return 0
        return 1 if raw < half else -1
    raise ValueError(f"unknown relative encoding {encoding!r}; expected one of {', '.join(ENCODINGS)}")
