"""A clock for the live loop's scheduling tests: time moves only when slept on."""

from __future__ import annotations


class FakeClock:
    """A clock that only moves when slept on (call it for the time, `sleep` to move it)."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(s, 0.0)
