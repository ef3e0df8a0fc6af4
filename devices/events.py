"""Control events: what every device backend produces and every consumer reads."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

EventKind = Literal["button", "dial", "axis", "key"]


@dataclass(frozen=True, slots=True)
class ControlEvent:
    """One change of one control.

    device:  the spec of the device that produced it (e.g. ``sgi:///dev/ttyUSB0``).
    control: ``dial3``, ``button17``, ``x``, ``key:A`` or a DBC signal name.
    kind:    ``button`` (value 0/1), ``dial`` (relative; value = signed change in turns),
             ``axis`` (absolute; value normalised to the declared range), ``key`` (0/1).
    value:   see kind.
    delta:   for dials the raw signed count change, else None.
    raw:     the undecoded value as read (counts, byte code, key name...), for logs and replay.
    t:       ``time.monotonic()`` taken as close to the read as possible, seconds.
    """

    device: str
    control: str
    kind: EventKind
    value: float
    delta: float | None = None
    raw: int | float | str | None = None
    t: float = 0.0


@dataclass(frozen=True, slots=True)
class StatusEvent:
    """A device came or went: status is ``connected`` or ``lost``; detail says why."""

    device: str
    status: Literal["connected", "lost"]
    t: float = 0.0
    detail: str = ""
