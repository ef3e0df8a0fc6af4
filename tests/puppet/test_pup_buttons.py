"""Button modes on scripted presses."""

from __future__ import annotations

import pytest

from puppet.mapping.buttons import ButtonState, RadioGroup

DT = 1.0 / 60.0


def test_momentary_follows_the_button_and_keeps_short_taps() -> None:
    b = ButtonState("momentary")
    b.press(True)
    assert b.level(DT) == 1.0
    b.press(False)
    assert b.level(DT) == 0.0
    b.press(True)
    b.press(False)  # tap inside one tick
    assert b.level(DT) == 1.0
    assert b.level(DT) == 0.0


def test_toggle_flips_on_press_only() -> None:
    b = ButtonState("toggle")
    for down, want in [(True, 1.0), (False, 1.0), (True, 0.0), (False, 0.0)]:
        b.press(down)
        assert b.level(DT) == want
    assert not b.is_on()


def test_radio_group_keeps_one_on() -> None:
    g = RadioGroup("presets", allow_none=True)
    a, b = ButtonState("radio", g), ButtonState("radio", g)
    a.press(True)
    a.press(False)
    assert (a.level(DT), b.level(DT)) == (1.0, 0.0)
    b.press(True)
    assert (a.level(DT), b.level(DT)) == (0.0, 1.0)
    b.press(False)
    b.press(True)  # pressing the active one again clears the group
    assert (a.level(DT), b.level(DT)) == (0.0, 0.0)
    g2 = RadioGroup("strict", allow_none=False)
    c = ButtonState("radio", g2)
    c.press(True)
    c.level(DT)
    c.press(False)
    c.press(True)
    assert c.level(DT) == 1.0


def test_trigger_envelope_attack_hold_release() -> None:
    b = ButtonState("trigger", attack=0.1, hold=0.2, release=0.1)
    b.press(True)
    b.press(False)
    levels = [b.level(DT) for _ in range(40)]
    assert levels[2] == pytest.approx(0.5)          # halfway through the attack at 3 ticks
    assert levels[5:18] == [1.0] * 13                 # held
    assert 0.0 < levels[20] < 1.0                     # releasing
    assert levels[-1] == 0.0 and not b.is_on()        # back to rest, by itself
    assert max(levels) == 1.0


def test_trigger_retrigger_does_not_jump() -> None:
    b = ButtonState("trigger", attack=0.1, hold=0.0, release=0.5)
    b.press(True)
    levels = [b.level(DT) for _ in range(12)]
    b.press(False)
    b.press(True)
    nxt = b.level(DT)
    assert abs(nxt - levels[-1]) < 0.2


def test_reset_turns_everything_off() -> None:
    g = RadioGroup("g")
    b = ButtonState("radio", g)
    b.press(True)
    b.level(DT)
    b.reset()
    assert g.active is None and b.level(DT) == 0.0
