"""Every shipped map loads against the real face, and every device kind gets one."""

from __future__ import annotations

import pytest

from devices.events import ControlEvent
from puppet.mapping import Mapper, Vocabulary
from puppet.mapping.defaults import default_map_name, load_default_map, map_names, merge


@pytest.fixture(scope="module")
def vocab() -> Vocabulary:
    from sim.channels import CHANNEL_SPECS
    from sim.facs import AU_TABLE, EXPRESSIONS
    from puppet.mapping import ChannelInfo

    return Vocabulary([ChannelInfo(c.name, c.kind, c.lo, c.hi, c.default) for c in CHANNEL_SPECS],
                      AU_TABLE, EXPRESSIONS)


@pytest.mark.parametrize("name", map_names())
def test_shipped_map_resolves(name: str, vocab: Vocabulary) -> None:
    m = Mapper(load_default_map(name), vocab)
    assert m.bindings


@pytest.mark.parametrize(
    "spec,want",
    [("sgi:///dev/ttyS0", "sgi"), ("keyboard://", "keyboard"), ("hid://077d:0410", "powermate"),
     ("hid://0b33:0020", "shuttlexpress"), ("hid://05f3:0405", "xkeys"), ("firmata:///dev/ttyACM0", "firmata"),
     ("serial:///dev/ttyUSB1?baud=115200", "textbox"), ("mock://?impersonate=sgi", "sgi")],
)
def test_device_gets_a_map(spec: str, want: str) -> None:
    assert default_map_name(spec) == want and want in map_names()


def test_sgi_map_drives_age_and_seven_muscle_groups(vocab: Vocabulary) -> None:
    spec = load_default_map("sgi")
    dials = {b.control for b in spec.bindings if b.control.startswith("dial")}
    assert dials == {f"dial{i}" for i in range(8)}
    assert any(b.control == "dial0" and b.target == "age" for b in spec.bindings)
    assert sum(1 for b in spec.bindings if b.control.startswith("button")) >= 30


def test_merged_maps_keep_devices_apart(vocab: Vocabulary) -> None:
    a, b = "sgi:///dev/ttyS0", "sgi:///dev/ttyS1"
    m = Mapper(merge([(load_default_map("sgi"), a), (load_default_map("sgi"), b)]), vocab)
    jaw = [c.name for c in vocab.channels].index("jaw")
    m.feed(ControlEvent(a, "dial7", "dial", 0.5))
    for _ in range(60):
        v = m.step(1 / 60)
    assert v[jaw] == pytest.approx(0.5, abs=1e-3)
    m.feed(ControlEvent(b, "button0", "button", 1.0))  # radio group of box b
    m.feed(ControlEvent(a, "button1", "button", 1.0))  # radio group of box a
    m.step(1 / 60)
    lit = {(d, c) for d, c, on in m.light_changes() if on}
    assert {(b, "button0"), (a, "button1")} <= lit


def test_can_panel_map_uses_the_example_dbc_signals() -> None:
    import re
    from pathlib import Path

    dbc = Path(__file__).resolve().parents[2] / "examples" / "can" / "j1939_bjm1.dbc"
    signals = set(re.findall(r"^\s*SG_ (\w+)", dbc.read_text(), re.M))
    spec = load_default_map("can_panel")
    assert {b.control for b in spec.bindings} <= signals
    assert default_map_name(f"can://virtual/panel?dbc={dbc}") == "can_panel"


def test_gamepad_found_by_description() -> None:
    assert default_map_name("hid://046d:c21d", "Logitech Gamepad F310 (gamepad, from its descriptor)") == "gamepad"


def test_keyboard_y_widens_the_eyes_and_releases(vocab: Vocabulary) -> None:
    """Holding Y raises both upper lids (AU5, the levator palpebrae) and letting go relaxes them."""
    m = Mapper(load_default_map("keyboard"), vocab)
    names = [c.name for c in vocab.channels]
    lids = [names.index("levator_palpebrae_l"), names.index("levator_palpebrae_r")]
    m.feed(ControlEvent("keyboard://", "key:Y", "button", 1.0))
    for _ in range(60):
        v = m.step(1 / 60)
    assert all(v[i] > 0.95 for i in lids)
    m.feed(ControlEvent("keyboard://", "key:Y", "button", 0.0))
    for _ in range(90):
        v = m.step(1 / 60)
    assert all(v[i] < 0.05 for i in lids)
