"""Mapping files: parsing errors with file:line:col, targets, combine rules, soft takeover, panic."""

from __future__ import annotations

import pytest

from puppet.errors import ConfigError
from puppet.mapping import parse_mapping
from puppet_helpers import DT, ev, idx, mapper


def run(m, events_by_tick: dict[int, list], ticks: int):  # type: ignore[no-untyped-def]
    out = []
    for k in range(ticks):
        for e in events_by_tick.get(k, []):
            m.feed(e)
        out.append(m.step(DT))
    return out


def test_syntax_error_names_line_and_column() -> None:
    with pytest.raises(ConfigError) as e:
        parse_mapping('name = "x"\n[[binding]]\ncontrol = "dial0\n', "my.toml")
    msg = str(e.value)
    assert msg.startswith("my.toml:3:") and "\n" not in msg


def test_semantic_error_points_at_the_key() -> None:
    text = ('name = "x"\n\n[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\n\n[[binding]]\ncontrol = "dial1"\n'
            'target = "jaw"\nfilters = [{type = "smooth", rise = "fast"}]\n')
    with pytest.raises(ConfigError, match=r"^m.toml:10:\d+: expected a number for rise"):
        parse_mapping(text, "m.toml")
    bad_mode = text.replace('filters = [{type = "smooth", rise = "fast"}]', 'mode = "latch"')
    with pytest.raises(ConfigError, match=r"^m.toml:10:1: expected one of momentary, toggle, radio, trigger"):
        parse_mapping(bad_mode, "m.toml")


def test_unknown_target_is_located_and_lists_choices() -> None:
    text = '[[binding]]\ncontrol = "a"\ntarget = "jaw"\n[[binding]]\ncontrol = "b"\n  target = "zygomatic"\n'
    with pytest.raises(ConfigError) as e:
        mapper(text)
    assert str(e.value).startswith("test.toml:6:3: unknown target 'zygomatic'")
    assert "zygomaticus_major" in str(e.value)


def test_pair_target_drives_both_sides_and_au_expands() -> None:
    m = mapper('[[binding]]\ncontrol = "x"\ntarget = "zygomaticus_major"\npickup = false\n'
               '[[binding]]\ncontrol = "y"\ntarget = "AU26"\npickup = false\n')
    v = run(m, {0: [ev("x", 0.6), ev("y", 1.0)]}, 1)[-1]
    assert v[idx("zygomaticus_major_l")] == v[idx("zygomaticus_major_r")] == pytest.approx(0.6)
    assert v[idx("jaw")] == pytest.approx(0.5)  # AU26 weight 0.5 on jaw


def test_relative_dial_with_gain_starts_at_default() -> None:
    m = mapper('[[binding]]\ncontrol = "dial0"\ntarget = "age"\ngain = 0.25\n')
    v = run(m, {1: [ev("dial0", 1.0, "dial")], 2: [ev("dial0", -0.5, "dial")]}, 3)
    assert v[0][idx("age")] == 30.0
    assert v[1][idx("age")] == pytest.approx(30 + 0.25 * 120)
    assert v[2][idx("age")] == pytest.approx(30 + 0.125 * 120)


def test_relative_encoding_from_raw_bytes() -> None:
    m = mapper('[[binding]]\ncontrol = "enc"\ntarget = "jaw"\ninput = "relative"\nencoding = "binary_offset"\n'
               'counts_per_turn = 10\n')
    v = run(m, {0: [ev("enc", 0, "axis", raw=67)], 1: [ev("enc", 0, "axis", raw=62)]}, 2)
    assert v[0][idx("jaw")] == pytest.approx(0.3) and v[1][idx("jaw")] == pytest.approx(0.1)


def test_absolute_axis_with_range_invert_curve() -> None:
    m = mapper('[[binding]]\ncontrol = "x"\ntarget = "jaw"\nfrom = [-1.0, 1.0]\npickup = false\n'
               'filters = [{type = "invert"}, {type = "curve", gamma = 2.0}]\n')
    v = run(m, {0: [ev("x", 0.0)]}, 1)[-1]
    assert v[idx("jaw")] == pytest.approx(0.25)


def test_combine_rules_max_sum_last() -> None:
    base = ('[[binding]]\ncontrol = "a"\ntarget = "jaw"\npickup = false\n'
            '[[binding]]\ncontrol = "b"\ntarget = "jaw"\npickup = false\n')
    evs = {0: [ev("a", 0.7), ev("b", 0.4)], 1: [ev("b", 0.5)]}
    v = run(mapper(base), evs, 2)
    assert v[1][idx("jaw")] == pytest.approx(0.7)                      # max
    v = run(mapper(base + '[combine]\njaw = "sum"\n'), evs, 2)
    assert v[1][idx("jaw")] == 1.0                                      # clamped sum
    v = run(mapper(base + '[combine]\ndefault = "last"\n'), evs, 2)
    assert v[0][idx("jaw")] == pytest.approx(0.4)                      # same tick: later binding
    assert v[1][idx("jaw")] == pytest.approx(0.5)                      # b moved last
    v = run(mapper(base + '[combine]\njaw = "last"\n'), {0: [ev("a", 0.7), ev("b", 0.4)], 1: [ev("a", 0.2)]}, 2)
    assert v[1][idx("jaw")] == pytest.approx(0.2)


def test_soft_takeover_waits_for_the_control_to_meet_the_value() -> None:
    m = mapper('[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\n'
               '[[binding]]\ncontrol = "fader"\ntarget = "jaw"\n[combine]\njaw = "last"\n')
    evs = {0: [ev("dial0", 0.6, "dial")],       # relative dial sets jaw 0.6
           2: [ev("fader", 0.1)],               # fader far below: must not jump
           3: [ev("fader", 0.3)],
           4: [ev("fader", 0.62)],              # crosses 0.6: picked up
           5: [ev("fader", 0.2)]}               # now it drives
    v = [x[idx("jaw")] for x in run(m, evs, 6)]
    assert v[2] == v[3] == pytest.approx(0.6)
    assert v[4] == pytest.approx(0.62) and v[5] == pytest.approx(0.2)


def test_button_modes_through_the_mapper_and_lights() -> None:
    m = mapper('[[binding]]\ncontrol = "button0"\ntarget = "expr:happiness"\nmode = "toggle"\n'
               '[[binding]]\ncontrol = "button1"\ntarget = "AU45"\nmode = "trigger"\nattack = 0.0\nhold = 0.05\n'
               'release = 0.05\n')
    press = [ev("button0", 1, "button"), ev("button0", 0, "button")]
    v = run(m, {0: press}, 2)
    assert v[1][idx("zygomaticus_major_l")] == pytest.approx(0.8)
    assert m.light_changes() == [("mock://", "button0", True)]
    v = run(m, {0: press, 1: [ev("button1", 1, "button")]}, 20)
    assert v[0][idx("zygomaticus_major_l")] == 0.0
    lid = [x[idx("orbicularis_oculi_lid_l")] for x in v]
    assert lid[1] == 1.0 and lid[-1] == 0.0       # a blink fires and ends by itself
    assert ("mock://", "button0", False) in m.light_changes()


def test_device_filter_and_actions() -> None:
    m = mapper('[[binding]]\ncontrol = "b"\ndevice = "sgi"\ntarget = "jaw"\n'
               '[[binding]]\ncontrol = "m"\naction = "marker"\nlabel = "take"\n')
    v = run(m, {0: [ev("b", 1, "button", device="powermate://x"), ev("m", 1, "button")]}, 1)
    assert v[0][idx("jaw")] == 0.0
    assert m.take_markers() == ["take"]
    v = run(m, {0: [ev("b", 1, "button", device="sgi:///dev/ttyS0")]}, 1)
    assert v[0][idx("jaw")] == 1.0


def test_panic_eases_to_neutral_and_resets_bindings() -> None:
    m = mapper('[[binding]]\ncontrol = "b"\ntarget = "jaw"\nmode = "toggle"\n'
               '[[binding]]\ncontrol = "d"\ntarget = "age"\n')
    run(m, {0: [ev("b", 1, "button"), ev("d", 0.5, "dial")]}, 2)
    m.panic()
    v = [m.step(DT) for _ in range(60)]
    jaw = [x[idx("jaw")] for x in v]
    assert all(a >= b for a, b in zip(jaw, jaw[1:])) and jaw[0] > 0.9 and jaw[-1] == 0.0
    assert v[-1][idx("age")] == 30.0
    assert not m.bindings[0].button.is_on()


def test_status_events_show_on_hud() -> None:
    from devices.events import StatusEvent

    m = mapper('[[binding]]\ncontrol = "b"\ntarget = "jaw"\n')
    assert m.binding_status() == [("b", "jaw", "waiting")]
    run(m, {0: [ev("b", 1, "button")]}, 1)
    assert m.binding_status()[0][2] == "connected"
    m.feed(StatusEvent("mock://", "lost"))
    assert m.binding_status()[0][2] == "lost" and "LOST" in m.hud_lines()[0]


def test_relative_nudges_continue_from_the_current_value() -> None:
    m = mapper('[[binding]]\ncontrol = "key:9"\ntarget = "age"\ninput = "relative"\ngain = 0.05\n'
               '[[binding]]\ncontrol = "key:8"\ntarget = "age"\ninput = "relative"\ngain = -0.05\n')
    up, down = ev("key:9", 1, "key"), ev("key:8", 1, "key")
    rel = lambda c: ev(c, 0, "key")  # noqa: E731
    v = run(m, {0: [up, rel("key:9")], 1: [up, rel("key:9")], 2: [down, rel("key:8")]}, 3)
    ages = [x[idx("age")] for x in v]
    assert ages == pytest.approx([36.0, 42.0, 36.0])


def test_a_lost_device_releases_held_buttons_but_keeps_toggles() -> None:
    from devices.events import StatusEvent

    m = mapper('[[binding]]\ncontrol = "held"\ntarget = "jaw"\n'
               '[[binding]]\ncontrol = "tog"\ntarget = "zygomaticus_major"\nmode = "toggle"\n')
    v = run(m, {0: [ev("held", 1, "button"), ev("tog", 1, "button")]}, 2)
    assert v[-1][idx("jaw")] == 1.0
    m.feed(StatusEvent("mock://", "lost"))
    v = m.step(DT)
    assert v[idx("jaw")] == 0.0 and v[idx("zygomaticus_major_l")] == 1.0
