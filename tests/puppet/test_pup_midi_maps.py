"""The default maps of the MIDI controller profiles: every bound control exists on the box, the
right map is chosen for a spec, and a nanoKONTROL2's faders, buttons and lights work through the
mapper (pickup, radio presets lit, rings following the channel, pickup re-armed after a replug)."""

from __future__ import annotations

import pytest

from devices.events import ControlEvent, StatusEvent
from devices.midi.profile import load_profile, profile_names
from puppet.live import load_face
from puppet.mapping import Mapper
from puppet.mapping.defaults import default_map_name, load_default_map, map_names, merge

MIDI_MAPS = [p for p in profile_names() if p != "generic"]


@pytest.fixture(scope="module")
def vocab():
    return load_face().vocab


@pytest.mark.parametrize("name", MIDI_MAPS)
def test_each_profile_has_a_map_whose_controls_exist(name: str, vocab) -> None:
    assert name in map_names()
    spec = load_default_map(name)
    Mapper(spec, vocab)  # every target resolves
    declared = {c.name for c in load_profile(name).controls}
    missing = {b.control for b in spec.bindings} - declared
    assert not missing, f"{name}.toml binds controls the box does not have: {missing}"
    kinds = {b.control: load_profile(name).control(b.control).kind for b in spec.bindings}
    assert "button" in kinds.values() and {"axis", "dial"} & set(kinds.values())


@pytest.mark.parametrize("spec, want", [
    ("midi://nanoKONTROL2?api=jack", "nanokontrol2"),
    ("midi://whatever?profile=bcr2000&api=alsa", "bcr2000"),
    ("midi://X-TOUCH MINI", "xtouch_mini"),
    ("rawmidi:///dev/snd/midiC1D0?profile=midimix", "midimix"),
    ("midi://Some Synth?api=jack", None),
])
def test_a_midi_spec_gets_its_profile_map(spec: str, want: str | None) -> None:
    assert default_map_name(spec) == want


def test_nanokontrol2_through_the_mapper(vocab) -> None:
    dev = "midi://nanoKONTROL2?api=jack"
    m = Mapper(merge([(load_default_map("nanokontrol2"), dev)]), vocab)
    m.declare_controls(dev, [])
    names = [c.name for c in vocab.channels]
    smile, jaw = names.index("zygomaticus_major_l"), names.index("jaw")

    def run(events: list[object], ticks: int = 30):
        for e in events:
            m.feed(e)
        for _ in range(ticks):
            v = m.step(1 / 60)
        return v

    # a fader far from the value does nothing until it crosses it (soft takeover), then drives
    assert run([ControlEvent(dev, "fader1", "axis", 0.9)])[smile] == 0.0
    assert run([ControlEvent(dev, "fader1", "axis", 0.0), ControlEvent(dev, "fader1", "axis", 0.5)])[smile] > 0.2
    # S1 lights as the active preset; S2 takes over the radio group and the light
    run([ControlEvent(dev, "s1", "button", 1.0), ControlEvent(dev, "s1", "button", 0.0)], 2)
    lit = {(c, on) for d, c, on in m.light_changes()}
    assert ("s1", True) in lit
    run([ControlEvent(dev, "s2", "button", 1.0), ControlEvent(dev, "s2", "button", 0.0)], 2)
    lit = {(c, on) for d, c, on in m.light_changes()}
    assert ("s1", False) in lit and ("s2", True) in lit
    # the knob bound to jaw... is not: fader7 drives the jaw; its "ring" level follows the channel
    run([ControlEvent(dev, "fader7", "axis", 0.0), ControlEvent(dev, "fader7", "axis", 0.6)], 40)
    rings = {c: lvl for d, c, lvl in m.light_changes() if not isinstance(lvl, bool)}
    assert rings["fader7"] == pytest.approx(0.6, abs=0.02)
    # unplug, replug: the faders wait for pickup again, nothing jumps
    before = run([StatusEvent(dev, "lost"), StatusEvent(dev, "connected")], 2)[jaw]
    after = run([ControlEvent(dev, "fader7", "axis", 0.1)], 30)[jaw]
    assert after == pytest.approx(before)


def test_a_learned_relative_encoder_under_its_generic_name_turns_its_channel(vocab) -> None:
    from puppet.mapping import parse_mapping

    text = ('[[binding]]\ncontrol = "ch1.cc80"\ndevice = "midi"\ntarget = "jaw"\ninput = "relative"\n'
            'encoding = "twos_complement"\ncounts_per_turn = 10\n')
    m = Mapper(parse_mapping(text, "learned.toml"), vocab)
    jaw = [c.name for c in vocab.channels].index("jaw")
    for raw in (1, 1, 1, 1, 127):  # four ticks up, one down: 3 counts of 10 a turn
        m.feed(ControlEvent("midi://box?api=jack", "ch1.cc80", "axis", raw / 127, None, raw))
    assert m.step(1 / 60)[jaw] == pytest.approx(0.3)
