"""The control sets of known boxes, shared by their backends and by ``mock://`` impersonation,
so a scripted rehearsal declares exactly the controls the real box will."""

from __future__ import annotations

from devices.base import ControlInfo

#: A dial event's value is its change in turns; one event never exceeds one turn either way.
DIAL_LO, DIAL_HI = -1.0, 1.0


def dials(n: int, prefix: str = "dial") -> list[ControlInfo]:
    """``n`` relative dials named ``dial0``..."""
    return [ControlInfo(f"{prefix}{i}", "dial", DIAL_LO, DIAL_HI) for i in range(n)]


def buttons(n: int, lights: bool = False, start: int = 0) -> list[ControlInfo]:
    """``n`` buttons named ``button<start>``..., optionally lit."""
    return [ControlInfo(f"button{i}", "button", 0.0, 1.0, lights) for i in range(start, start + n)]


def axes(n: int, lo: float = 0.0, hi: float = 1.0) -> list[ControlInfo]:
    """``n`` absolute axes named ``axis0``..."""
    return [ControlInfo(f"axis{i}", "axis", lo, hi) for i in range(n)]


def sgi_controls() -> list[ControlInfo]:
    """SGI dial-and-button box: 8 dials, 32 lit buttons."""
    return dials(8) + buttons(32, lights=True)


def powermate_controls() -> list[ControlInfo]:
    """Griffin PowerMate: the knob, its push button and the LED under it (the button's light)."""
    return [ControlInfo("knob", "dial", DIAL_LO, DIAL_HI), ControlInfo("button0", "button", 0, 1, True)]


def shuttle_controls(n_buttons: int) -> list[ControlInfo]:
    """Contour ShuttleXpress (5 buttons) / ShuttlePro (15): spring-loaded ring, jog wheel, buttons."""
    return [
        ControlInfo("shuttle", "axis", -1.0, 1.0),
        ControlInfo("jog", "dial", DIAL_LO, DIAL_HI),
        *buttons(n_buttons),
    ]


def text_controls(n_buttons: int = 16, n_dials: int = 8, n_axes: int = 8) -> list[ControlInfo]:
    """A home-made box speaking the text protocol (sizes come from the spec options)."""
    return buttons(n_buttons, lights=True) + dials(n_dials) + axes(n_axes)


def firmata_controls() -> list[ControlInfo]:
    """An Arduino Uno under StandardFirmata with the backend's default pins: A0-A5, D2-D12."""
    return axes(6) + buttons(11, start=2)


def keyboard_controls() -> list[ControlInfo]:
    """The keyboard fallback's declared keys."""
    from devices.keyboard import _NAMED

    return [ControlInfo(f"key:{n}", "key", 0.0, 1.0) for n in _NAMED]


CONTROL_SETS = {
    "sgi": sgi_controls,
    "powermate": powermate_controls,
    "shuttlexpress": lambda: shuttle_controls(5),
    "shuttlepro": lambda: shuttle_controls(15),
    "serial": text_controls,
    "firmata": firmata_controls,
    "keyboard": keyboard_controls,
}


def control_set(name: str) -> list[ControlInfo]:
    """The controls of the named box; KeyError lists the known names."""
    try:
        return CONTROL_SETS[name.lower()]()
    except KeyError:
        raise KeyError(f"unknown box {name!r}; known: {', '.join(sorted(CONTROL_SETS))}") from None
