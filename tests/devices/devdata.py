"""Shared test data and helpers for tests/devices: real HID captures, example DBC paths, and
waiting for events on an EventQueue without sleeping."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from devices import ControlEvent, EventQueue

EXAMPLES = Path(__file__).parents[2] / "examples"
PANEL_DBC = EXAMPLES / "can" / "panel.dbc"
BJM1_DBC = EXAMPLES / "can" / "j1939_bjm1.dbc"

# LeafLabs Maple joystick, a hid-recorder capture (R: descriptor, E: first report) published with
# an off-brand handbrake driver; hid-recorder decoded that report as X 512, Y 512, Rx 0, Ry 0,
# Slider 0 and 7, hat 15 (null), no buttons.
MAPLE_RDESC = bytes.fromhex(
    "05 01 09 04 a1 01 85 14 15 00 25 01 75 01 95 20 05 09 19 01 29 20 81 02 15 00 25 07 35 00 46 3b"
    " 01 75 04 95 01 65 14 05 01 09 39 81 42 05 01 09 01 a1 00 15 00 26 ff 03 75 0a 95 04 09 30 09 31"
    " 09 33 09 34 81 02 c0 15 00 26 ff 03 75 0a 95 02 09 36 09 36 81 02 c0")
MAPLE_REPORT = bytes.fromhex("14 00 00 00 00 0f 20 80 00 00 00 c0 01")

# Contour RollerMouse Red (0b33:1004), hid-recorder capture from the bthidhub docs: report 1 with
# button 1 pressed then released; relative X/Y, wheel; also keyboard and consumer reports.
ROLLER_RDESC = bytes.fromhex(
    "05 01 09 02 a1 01 09 01 a1 01 85 01 05 09 19 01 29 08 15 00 25 01 75 01 95 08 81 02"
    " 05 01 09 30 09 31 16 08 80 26 ff 7f 75 10 95 02 81 06 09 38 15 81 25 7f 75 08 95 01 81 06"
    " 05 0c 0a 00 ff 81 06 06 00 ff 09 01 75 08 95 08 81 02 c0 c0 05 01 09 06 a1 01 85 02 05 07"
    " 19 e0 29 e7 15 00 25 01 75 01 95 08 81 02 06 00 ff 09 02 75 08 95 01 81 02 05 07 19 00 29"
    " 7f 15 00 25 7f 75 08 95 05 81 00 c0 05 0c 09 01 a1 01 85 03 05 09 19 09 29 18 15 00 25 01"
    " 75 01 95 10 81 02 05 0c 19 00 2a ff 03 15 00 26 ff 03 95 01 75 10 81 00 05 01 1a 81 00 2a"
    " 83 00 15 00 25 01 75 01 95 03 81 02 95 05 81 01 06 00 ff 09 02 75 08 95 0a 81 02 85 04 06"
    " 00 ff 0a 00 ff 75 08 95 0f b1 02 c0")
ROLLER_EVENTS = [bytes.fromhex(h) for h in (
    "01 00 00 00 00 00 00 00 01 80 00 00 00 00 00 00",
    "01 01 00 00 00 00 00 00 01 80 00 00 00 00 00 00",
    "01 00 00 00 00 00 00 00 01 80 00 00 00 00 00 00",
)]



def wait_for(q: EventQueue, pred: Callable[[Any], bool], timeout: float = 5.0) -> list[Any]:
    """Events up to and including the first matching one."""
    seen: list[Any] = []
    while True:
        e = q.get(timeout=timeout)
        assert e is not None, f"timed out; saw {seen}"
        seen.append(e)
        if pred(e):
            return seen


def controls(events: list[Any]) -> list[ControlEvent]:
    return [e for e in events if isinstance(e, ControlEvent)]
